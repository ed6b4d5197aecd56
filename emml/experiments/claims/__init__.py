"""The paper's claims: as data (claim.py, reproduce/claims.toml), their kinds (kinds.py) and the rules that weigh
their evidence (evidence.py). The reports gather the evidence and write the page (emml/report/claims.py)."""

from emml.experiments.claims.claim import CLAIMS_FILE, Claim, load_claims
from emml.experiments.claims.kinds import KINDS

__all__ = ["CLAIMS_FILE", "KINDS", "Claim", "load_claims"]
