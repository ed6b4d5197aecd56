"""Scoring and diagnosing a model: greedy evaluation (evaluate.py), the diagnostics of every evaluation
(diagnose.py) with EQA's and SGN's own (diagnose_eqa.py, diagnose_sgn.py), the EQA encoder probe (probe_eqa.py),
Table 4's transfer to new words (transfer.py) and re-scoring a finished run (rescore.py)."""
