"""The experiments: the paper's tables and our own as data (tables.py, reproduce/*.toml), a table's runs launched
on a local pool or Slurm (launch.py), ordered multi-table campaigns (campaign.py), and the paper's declared
settings held against a run's config (fidelity.py)."""
