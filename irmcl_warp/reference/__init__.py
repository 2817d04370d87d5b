"""Readable numpy twins of the Warp kernels, one per registry entry, used by the parity tests."""
