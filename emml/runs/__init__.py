"""A run's one owner: its dir, name and identity (rundir.py), its checkpoint (checkpoint.py), the lock of the process
training it (runlock.py), its results row (results.py), its MLflow run (tracking.py: the tracker; store.py: the store
through MLflow's public API; provenance.py, portable.py: what its tags and params say; mirror.py: its metrics.csv),
the checks before it starts (preflight.py, diskspace.py) and committed run dirs imported into the store
(import_runs.py, the import's one owner)."""
