"""Model configuration for the EMML model zoo.

Reproduces the architectures of "Embodied Multimodal Multitask Learning"
(Chaplot et al. 2019, arXiv 1902.01385): the Dual-Attention model, its
ablations, and the six multimodal-fusion baselines of the appendix.
"""

from __future__ import annotations

from dataclasses import dataclass

ARCHITECTURES: tuple[str, ...] = (
    "text_only",
    "image_only",
    "concat",
    "ga",
    "film",
    "pacman",
    "dual_attention",
)
"""Fusion architectures a `ModelConfig.name` may name (ablations are switches)."""


@dataclass
class ModelConfig:
    """Hyperparameters of one model; every model shares encoders and policy."""

    name: str = "dual_attention"
    """Fusion architecture, one of `ARCHITECTURES` (ablations use the switches below)."""
    embed_dim: int = 32
    """Word-embedding size (paper appendix: 32)."""
    gru_text: int = 32
    """Hidden size of the sentence GRU (paper appendix: 32)."""
    hidden: int = 128
    """Hidden size of the policy's linear layer and GRU (paper appendix: 128)."""
    time_dim: int = 32
    """Size of the learned time-step embedding (paper is silent; our choice)."""
    pacman_frames: int = 5
    """Frames in the PACMAN attention window, current frame included (paper: 5)."""
    spatial_attention: bool = True
    """Dual-Attention: use the Spatial-Attention unit (Eq. 2-3); False = 'w/o SA' ablation."""
    ga1: bool = True
    """Dual-Attention: use the BoW Gated-Attention (Eq. 1); False = 'w/o GA1' ablation."""
    ga2: bool = True
    """Dual-Attention: use the sentence Gated-Attention (Eq. 4); False = 'w/o GA2' ablation."""
    task_indicator: bool = True
    """Feed the SGN/EQA task one-hot to the policy; False = 'w/o task indicator' ablation."""

    def validate(self) -> ModelConfig:
        """Raise `ValueError` naming the offending field; return self when valid."""
        if self.name not in ARCHITECTURES:
            raise ValueError(f"ModelConfig.name={self.name!r} is unknown; known names: " + ", ".join(ARCHITECTURES))
        for field in ("embed_dim", "gru_text", "hidden", "time_dim", "pacman_frames"):
            value = getattr(self, field)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"ModelConfig.{field}={value!r} must be a positive integer (>= 1)")
        for field in ("spatial_attention", "ga1", "ga2", "task_indicator"):
            value = getattr(self, field)
            if not isinstance(value, bool):
                raise ValueError(f"ModelConfig.{field}={value!r} must be True or False")
        if self.name != "dual_attention":
            for field in ("spatial_attention", "ga1", "ga2"):
                if not getattr(self, field):
                    raise ValueError(
                        f"ModelConfig.{field}=False is only allowed for "
                        f"name='dual_attention' (got name={self.name!r}); allowed: True"
                    )
        return self
