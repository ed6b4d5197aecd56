"""The baselines of "Embodied Multimodal Multitask Learning" (Chaplot et al. 2019, appendix "Baseline details"):
`TextOnly`, `ImageOnly`, `Concat`, `GatedAttention`, `FiLM`, whose answer head is x_Ans = softmax(ReLU(Linear(x_S)))
(`AnswerHead`), and `Pacman`, the QA attention of Das et al. 2018 over the last K frames. Each is a `Fusion`
(emml/models/fusion.py: the base class, its No Aux warm-up, and the proposed unit, Dual-Attention)."""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor, nn

from emml.config.checks import Positive
from emml.config.model import ACTIVATIONS
from emml.config.schema import model_option
from emml.models.encoders import activation_function
from emml.models.fusion import Fusion, FusionOptions, FusionOutput, gated_attention


@dataclass
class BaselineOptions(FusionOptions):
    """The option of the baselines with the appendix's answer head (Text only, Image only, Concat, GA, FiLM)."""

    answer_activation: str = model_option("relu", name="head{}", choices=ACTIVATIONS)
    """The activation on the answer head's logits (appendix, "Baseline details": "a linear layer f with ReLU
    activations followed by softmax"): 'relu', the paper's, the default; or, opt-in, 'softplus', as non-negative but
    never 0. Measured in docs/fidelity.md ("The baselines' answer head"): under ReLU a logit whose Linear output is
    negative on every frame gets no gradient from the answer loss, and its word is never answered again (Concat No
    Aux seed 0: 5 of the 9 answer words; Text only Aux: 'red' and 'blue'). Run name: 'head<activation>'."""


class AnswerHead(nn.Module):
    """Baseline answer head f: answer logits = ReLU(Linear(x_S)), x_Ans = softmax(logits).

    Appendix "Baseline details": x_Ans = sigma(f(x_S; theta_Lin)), f linear + ReLU; softplus in ReLU's place under
    `BaselineOptions.answer_activation`.
    """

    def __init__(self, state_dim: int, vocab_size: int) -> None:
        super().__init__()
        self.linear = nn.Linear(state_dim, vocab_size)
        self.activation = "relu"
        """The activation's name, one of `ACTIVATIONS` (`use`)."""
        self.function = activation_function(self.activation)
        """The activation on the logits."""

    def use(self, activation: str) -> AnswerHead:
        """Put ``activation`` (one of `ACTIVATIONS`) on the logits; returns self."""
        self.function = activation_function(activation, "answer_activation")
        self.activation = activation
        return self

    def forward(self, state: Tensor) -> Tensor:
        return self.function(self.linear(state))


class _Baseline(Fusion):
    """Shared plumbing: subclasses define `state()`, the head is `AnswerHead`.

    The No Aux warm-up (`Fusion.warming`): the head reads x_S computed again from x_I with its gradient stopped, so that
    the answer loss trains the head and the text side (x_BoW's and x_sent's encoders, FiLM's gamma and beta) and not
    the conv, while the policy reads x_S as always."""

    answer_warmup = True
    options = BaselineOptions

    def __init__(self, vocab_size: int, state_dim: int) -> None:
        super().__init__()
        self.state_dim = state_dim
        self.answer = AnswerHead(state_dim, vocab_size)

    @classmethod
    def from_config(cls, cfg, vocab_size: int, height: int, width: int) -> Fusion:
        fusion = cls(vocab_size, height, width)
        fusion.answer.use(cfg.options.answer_activation)  # no parameter drawn: a seed's weights as before
        return fusion

    def state(self, x_image: Tensor, x_bow: Tensor | None, x_sent: Tensor | None) -> Tensor:
        raise NotImplementedError

    def forward(self, x_image: Tensor, x_bow: Tensor | None, x_sent: Tensor | None) -> FusionOutput:
        state = self.state(x_image, x_bow, x_sent)
        read = self.state(x_image.detach(), x_bow, x_sent) if self.warming else state  # the warm-up: off the conv
        return FusionOutput(state=state, answer_logits=self.answer(read))


class TextOnly(_Baseline):
    """Text only: x_S = [x_BoW, x_sent]. Its answer reads no image: no warm-up (`answer_warmup` False)."""

    uses_bow = True
    uses_sent = True
    answer_warmup = False

    def __init__(self, vocab_size: int, height: int, width: int) -> None:
        super().__init__(vocab_size, 2 * vocab_size)

    def state(self, x_image, x_bow, x_sent):
        return torch.cat([x_bow, x_sent], dim=1)


class ImageOnly(_Baseline):
    """Image only: x_S = vec(x_I)."""

    def __init__(self, vocab_size: int, height: int, width: int) -> None:
        super().__init__(vocab_size, vocab_size * height * width)

    def state(self, x_image, x_bow, x_sent):
        return x_image.flatten(1)


class Concat(_Baseline):
    """Concat (Hermann et al. 2017; Misra et al. 2017): x_S = [vec(x_I), x_BoW, x_sent]."""

    uses_bow = True
    uses_sent = True

    def __init__(self, vocab_size: int, height: int, width: int) -> None:
        super().__init__(vocab_size, vocab_size * height * width + 2 * vocab_size)

    def state(self, x_image, x_bow, x_sent):
        return torch.cat([x_image.flatten(1), x_bow, x_sent], dim=1)


class GatedAttention(_Baseline):
    """Gated-Attention (Chaplot et al. 2018): x_S = vec(f_GA(x_I, x_sent))."""

    uses_sent = True

    def __init__(self, vocab_size: int, height: int, width: int) -> None:
        super().__init__(vocab_size, vocab_size * height * width)

    def state(self, x_image, x_bow, x_sent):
        return gated_attention(x_image, x_sent).flatten(1)


class FiLM(_Baseline):
    """FiLM (Perez et al. 2018): x_S = vec(gamma(x_sent) ⊙ x_I + beta(x_sent)).

    gamma and beta are Linear(V -> V) projections of x_sent, broadcast per channel.
    """

    uses_sent = True

    def __init__(self, vocab_size: int, height: int, width: int) -> None:
        super().__init__(vocab_size, vocab_size * height * width)
        self.gamma = nn.Linear(vocab_size, vocab_size)
        self.beta = nn.Linear(vocab_size, vocab_size)

    def state(self, x_image, x_bow, x_sent):
        gamma = self.gamma(x_sent)[:, :, None, None]
        beta = self.beta(x_sent)[:, :, None, None]
        return (gamma * x_image + beta).flatten(1)


@dataclass
class PacmanOptions(FusionOptions):
    """PACMAN's option (`Pacman.options`): its window of frames."""

    pacman_frames: Positive = model_option(5)
    """Frames in the PACMAN attention window, current frame included (paper: 5)."""


class Pacman(Fusion):
    """PACMAN QA attention (Das et al. 2018), adapted as in the appendix.

    Input: x_I of the last K frames (N, K, V, h, w), oldest first, and x_sent.

    * each frame is projected to a V-vector comparable with x_sent by a learned
      Linear(V*h*w -> V) on vec(x_I) (our choice; the paper only says "dot
      products between image and sentence-level text representations");
    * similarity s_k = <proj_k, x_sent>, attention a = softmax_k(s);
    * x_S = sum_k a_k vec(x_I,k) (attention-weighted image features);
    * answer logits = Linear([sum_k a_k proj_k, x_sent] -> V) (softmax classifier).

    The No Aux warm-up (`Fusion.warming`): the answer's attention and projections are computed again from the frames'
    x_I with its gradient stopped (the projection, the classifier and x_sent still learn from the answer).
    """

    uses_sent = True
    frame_window = "pacman_frames"
    options = PacmanOptions
    answer_warmup = True

    def __init__(self, vocab_size: int, height: int, width: int) -> None:
        super().__init__()
        self.state_dim = vocab_size * height * width
        self.project = nn.Linear(self.state_dim, vocab_size)
        self.classifier = nn.Linear(2 * vocab_size, vocab_size)

    def frame_attention(self, frames: Tensor, x_sent: Tensor) -> tuple[Tensor, Tensor]:
        """(N, K, V, h, w), (N, V) -> attention weights (N, K), projections (N, K, V)."""
        proj = self.project(frames.flatten(2))  # (N, K, V)
        scores = torch.einsum("nkv,nv->nk", proj, x_sent)  # dot-product similarity
        return torch.softmax(scores, dim=1), proj

    def forward(self, frames: Tensor, x_bow: Tensor | None, x_sent: Tensor) -> FusionOutput:
        weights, proj = self.frame_attention(frames, x_sent)
        state = torch.einsum("nk,nkd->nd", weights, frames.flatten(2))  # attended vec(x_I)
        if self.warming:  # the No Aux warm-up: the answer from the frames' x_I with its gradient stopped
            weights, proj = self.frame_attention(frames.detach(), x_sent)
        attended = torch.einsum("nk,nkv->nv", weights, proj)
        answer_logits = self.classifier(torch.cat([attended, x_sent], dim=1))
        return FusionOutput(state=state, answer_logits=answer_logits)
