"""The results library: run records (records.py), the questions tables ask of them (queries.py), the
papers' published figures (papers.py) and the registry of claims with their verdicts (claims.py)."""
