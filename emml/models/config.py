"""Model configuration for the EMML model zoo.

Reproduces the architectures of "Embodied Multimodal Multitask Learning"
(Chaplot et al. 2019, arXiv 1902.01385): the Dual-Attention model, its
ablations, and the six multimodal-fusion baselines of the appendix.
"""

from __future__ import annotations

from dataclasses import dataclass

from emml.models.registry import ARCHITECTURES, PLUGIN_HINT, architecture

CONTROLS: tuple[str, ...] = ("none", "detectors", "target_mask", "type_gate")
"""Values of `ModelConfig.control`: the model itself, and the three diagnostic controls."""
LABEL_CONTROLS: tuple[str, ...] = ("detectors", "target_mask")
"""The controls that read the env's privileged aux labels (acting needs them; training needs aux=True)."""


@dataclass
class ModelConfig:
    """Hyperparameters of one model; every model shares encoders and policy."""

    name: str = "dual_attention"
    """Fusion architecture, one of `ARCHITECTURES`: a fusion class of the model registry, emml/models/registry.py
    (ablations use the switches below)."""
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
    state_scale: bool = True
    """Dual-Attention: hand the policy x_S = h·w · vec(x_spat) (mean 1 per cell) instead of vec(x_spat) (entries
    ~1/(h·w)). Paper silent on input scaling; measured in docs/fidelity.md."""
    state_temperature: float | None = None
    """Dual-Attention, opt-in: hand the policy x_S = h·w · softmax(scores / state_temperature) with the gradient
    stopped, a sharper copy of x_spat (Eq. 2); x_spat itself, Eq. 3-5 and every loss's gradient into the detectors
    stay as they are. None (the default): x_S = h·w · vec(x_spat). The paper is silent on how the policy reads the
    map: at temperature 1 a detector that ranks the target first but scores it 0.6 against 0.2 gives it 1.5x a
    background cell, too faint for the actor; measured in docs/fidelity.md."""
    x_image: str = "sigmoid"
    """What the fusion reads as x_I from the conv3 logits z: 'sigmoid' (Appendix A: sigmoid on conv3) or 'relu'
    (§3.1 after Eq. 2: 'ReLU activations in the convolutional feature maps'); the aux task predicts sigmoid(z)
    either way. The paper contradicts itself; measured in docs/fidelity.md."""
    control: str = "none"
    """Diagnostic controls, not the paper's model (they read privileged labels, so they need aux labels):
    'none'; 'detectors': x_I := the aux labels (perfect detectors, unlabelled channels 0); 'target_mask':
    x_S := the cells showing the episode's referent (perfect x_S, values 0/1); 'type_gate' (Dual-Attention with GA2,
    evaluation only: `emml eval CKPT --control type_gate`): Eq. 4's x_sent := a gate from the dataset's word types
    that opens the channels of the attribute a question asks for (emml/models/type_gate.py), no labels read."""

    def validate(self) -> ModelConfig:
        """Raise `ValueError` naming the offending field; return self when valid."""
        if self.name not in ARCHITECTURES:
            raise ValueError(
                f"ModelConfig.name={self.name!r} is unknown; known names: {', '.join(ARCHITECTURES)}; {PLUGIN_HINT}"
            )
        for field in ("embed_dim", "gru_text", "hidden", "time_dim", "pacman_frames"):
            value = getattr(self, field)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"ModelConfig.{field}={value!r} must be a positive integer (>= 1)")
        t = self.state_temperature
        if t is not None and (isinstance(t, bool) or not isinstance(t, (int, float)) or not t > 0):
            raise ValueError(f"ModelConfig.state_temperature={t!r} must be None (off) or a number > 0")
        if t is not None and not (self.name == "dual_attention" and self.spatial_attention):
            raise ValueError(
                f"ModelConfig.state_temperature={t!r} sharpens the spatial attention map: only for "
                f"name='dual_attention' with spatial_attention=True (got name={self.name!r}, "
                f"spatial_attention={self.spatial_attention}); allowed there: None or a number > 0"
            )
        if self.x_image not in ("sigmoid", "relu"):
            raise ValueError(f"ModelConfig.x_image={self.x_image!r} is unknown; allowed: sigmoid, relu")
        if self.control not in CONTROLS:
            raise ValueError(f"ModelConfig.control={self.control!r} is unknown; allowed: " + ", ".join(CONTROLS))
        if self.control == "type_gate" and not (self.name == "dual_attention" and self.ga2):
            raise ValueError(
                f"ModelConfig.control='type_gate' replaces the GA2 gate (Eq. 4): only for name='dual_attention' "
                f"with ga2=True (got name={self.name!r}, ga2={self.ga2})"
            )
        for field in ("spatial_attention", "ga1", "ga2", "task_indicator", "state_scale"):
            value = getattr(self, field)
            if not isinstance(value, bool):
                raise ValueError(f"ModelConfig.{field}={value!r} must be True or False")
        for field in ("spatial_attention", "ga1", "ga2"):  # the ablations (§4) a fusion declares it reads
            if not getattr(self, field) and field not in architecture(self.name).ablations:
                readers = [a for a in ARCHITECTURES if field in architecture(a).ablations]
                raise ValueError(
                    f"ModelConfig.{field}=False is only allowed for "
                    f"name={' or '.join(map(repr, readers))} (got name={self.name!r}); allowed: True"
                )
        return self
