"""Evaluation: metrics over run outputs (metrics.json), tables and plots made from them."""
