"""The benchmarks (``python -m eval.bench train|mcl|slam|globloc``): each prints a table and writes a JSON record
(``timing.record_path``: one name per kind and device; results/bench/ keeps the current one of each)."""
