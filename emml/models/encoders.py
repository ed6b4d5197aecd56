"""Image and text encoders of "Embodied Multimodal Multitask Learning"
(Chaplot et al. 2019, arXiv 1902.01385), Section 3 and appendix
"Hyperparameters and network details".

* Image: conv1 32@8x8 stride 4 + ReLU, conv2 64@4x4 stride 2 + ReLU,
  conv3 V@3x3 stride 2 + sigmoid (no padding), V = vocabulary size, so that
  channel i of x_I is aligned with word i.
* Text: bag-of-words x_BoW in {0,1}^V and sentence embedding
  x_sent = ReLU(Linear_V(GRU_32(Embedding_32(T)))).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from emml.config.checks import check_choice
from emml.config.geometry import CONV_LAYERS as _CONV_LAYERS  # one source of the conv geometry
from emml.config.geometry import MIN_INPUT_SIZE, conv_output_size  # noqa: F401  (re-exported)
from emml.config.model import ACTIVATIONS
from emml.models.gru import gru_scan

BLOCKS_FROM = (64, 25_000)
"""Batches from which conv1 runs on pixel blocks: at least 64 frames of at least 25,000 pixels. Measured on a
2-core AVX-512 CPU (docs/throughput.md): the conv stack's forward + backward on the update's batch of 1,024 frames
took 0.71x the time (fp32) and 0.82x (bf16) at 168×300 (50,400 pixels), but 1.08x and 1.06x at 84×150 (12,600),
and acting's batches of 4-8 frames ran slower at both sizes."""


class ImageEncoder(nn.Module):
    """Conv stack f(I; theta_conv) -> conv3 pre-sigmoid logits (N, V, h, w).

    x_I = sigmoid(logits); the logits are also the auxiliary-task predictions
    (per-channel object/attribute detection), trained with cross-entropy.
    """

    def __init__(self, vocab_size: int) -> None:
        super().__init__()
        (k1, s1), (k2, s2), (k3, s3) = _CONV_LAYERS
        self.conv1 = nn.Conv2d(3, 32, kernel_size=k1, stride=s1)
        self.conv2 = nn.Conv2d(32, 64, kernel_size=k2, stride=s2)
        self.conv3 = nn.Conv2d(64, vocab_size, kernel_size=k3, stride=s3)
        # channels_last (NHWC) weights and activations: oneDNN's convolutions run faster on them (issue 14; conv
        # stack forward + backward 0.61x the time at 84x150, 0.82x at 168x300; docs/throughput.md); same values.
        self.to(memory_format=torch.channels_last)
        self.channels_last = True
        """Convert the input to channels_last (off under `torch.func.vmap`, which cannot query memory formats)."""
        self.bf16 = False
        """Run the convolutions in bf16 (TrainConfig.precision, set by emml/rl/precision.py); the logits are
        returned in fp32 either way."""
        self.blocks_from = BLOCKS_FROM
        """(batch, pixels per frame) from which conv1 runs on 4×4 pixel blocks (`_conv1_on_blocks`); None: never."""

    def _scaled(self, pixels: Tensor) -> Tensor:
        """uint8 pixels / 255 in the convolutions' dtype: straight to bf16 under `bf16`, the same values as the
        fp32 quotient cast to bf16 (one rounding of the same fp32 quotient) without the fp32 copy."""
        return pixels.to(torch.bfloat16 if self.bf16 else torch.float32).div_(255.0)

    def _conv(self, conv: nn.Conv2d, x: Tensor, blocks_kernel: Tensor | None = None) -> Tensor:
        """``conv`` of ``x`` (with ``blocks_kernel``, stride 1: conv1 on pixel blocks), in bf16 when `bf16` is set:
        inputs, weight and bias cast as autocast would, explicitly, as autocast does not reach under `vmap`."""
        weight, stride = (conv.weight, conv.stride) if blocks_kernel is None else (blocks_kernel, 1)
        bias = conv.bias
        if self.bf16:
            x, weight, bias = x.to(torch.bfloat16), weight.to(torch.bfloat16), bias.to(torch.bfloat16)
        return F.conv2d(x, weight, bias, stride)

    def _conv1_on_blocks(self, image: Tensor) -> Tensor:
        """conv1 of the scaled image, computed on its s×s pixel blocks (space to depth, s = conv1's stride 4).

        A k×k stride-s convolution equals a (k/s)×(k/s) stride-1 convolution over the image cut into s×s blocks:
        block channel (i, j, c) holds pixel (s·y + i, s·x + j) of channel c, and the kernel is cut the same way.
        Here: 2×2 on 48 channels instead of 8×8 on 3, the same weights and values within float tolerance. The
        rows and columns past the last block conv1 reads are dropped: conv1 never reads them either."""
        weight = self.conv1.weight
        out_ch, in_ch, k, _ = weight.shape
        s = self.conv1.stride[0]
        kb = k // s
        n, _, height, width = image.shape
        hb, wb = (height - k) // s + kb, (width - k) // s + kb  # blocks that conv1's windows cover
        # (N, H, W, C): a view of the rollout's frames as stored (emml/rl/rollout.py); one uint8 copy to
        # (N, hb, wb, s, s, C), which is the block tensor channels_last, the layout the other layers run in
        pixels = image[:, :, : hb * s, : wb * s].permute(0, 2, 3, 1).reshape(n, hb, s, wb, s, in_ch)
        blocks = pixels.permute(0, 1, 3, 2, 4, 5).contiguous().reshape(n, hb, wb, -1).permute(0, 3, 1, 2)
        kernel = weight.reshape(out_ch, in_ch, kb, s, kb, s).permute(0, 3, 5, 1, 2, 4).reshape(out_ch, -1, kb, kb)
        return self._conv(self.conv1, self._scaled(blocks), kernel)

    def _on_blocks(self, image: Tensor) -> bool:
        if self.blocks_from is None:
            return False
        batch, pixels = self.blocks_from
        return image.shape[0] >= batch and image.shape[-2] * image.shape[-1] >= pixels

    def forward(self, image: Tensor) -> Tensor:
        """uint8 image (N, 3, H, W) -> conv3 logits (N, V, h, w), contiguous (NCHW) like any other tensor."""
        if image.dtype != torch.uint8:
            raise TypeError(f"ImageEncoder expects a uint8 image, got {image.dtype}")
        if self._on_blocks(image):
            x = torch.relu(self._conv1_on_blocks(image))
        else:
            if self.channels_last:
                image = image.contiguous(memory_format=torch.channels_last)
            x = torch.relu(self._conv(self.conv1, self._scaled(image)))
        x = torch.relu(self._conv(self.conv2, x))
        logits = self._conv(self.conv3, x)
        return logits.to(torch.float32, memory_format=torch.contiguous_format)


ACTIVATION_FUNCTIONS = dict(zip(ACTIVATIONS, (torch.relu, F.softplus), strict=True))
"""The function of each activation an option may name (`emml.config.model.ACTIVATIONS`, in its order)."""


def activation_function(name: str, field: str = "activation"):
    """The function of activation ``name``; one that is not in `ACTIVATIONS` is a ValueError naming ``field`` and the
    allowed values."""
    check_choice(field, name, ACTIVATIONS)
    return ACTIVATION_FUNCTIONS[name]


DEDUPE_FROM = 64
"""Batches of at least this many rows encode each distinct instruction once (the PPO update's T·B rows hold one
instruction per episode: ~40 distinct in 1,024 at 84×150, a quarter of the encoder's time); acting's few rows
are encoded as they come."""


class TextEncoder(nn.Module):
    """Token ids (N, L) -> x_BoW (N, V) and x_sent (N, V) (Section 3).

    Token id 0 is padding and word index i has token id i + 1. Sequences are
    expected to be right-padded; x_sent reads the GRU output at the last
    non-padding position, and is ReLU(bias-only Linear) for an all-padding row.
    With ``sentence=False`` the GRU/Linear are not built and x_sent is None
    (for fusions that never read it, so no dead parameters exist).
    """

    def __init__(
        self,
        vocab_size: int,
        embed_dim: int = 32,
        gru: int = 32,
        sentence: bool = True,
        readout: str = "last",
        activation: str = "relu",
    ) -> None:
        super().__init__()
        self.vocab_size = vocab_size
        self.sentence = sentence
        self.readout = readout
        """Which GRU output the Linear reads: 'last' (after the last word) or 'mean' (over the words);
        `ModelConfig.sentence_readout`."""
        self.activation = activation_function(activation)
        """x_sent's activation on the Linear: ReLU (§3) or softplus; `ModelConfig.sentence_activation`."""
        self.unrolled = False
        """Run the GRU as its equations in linear ops (`gru_scan`) rather than the fused `nn.GRU` kernel: what
        `torch.func.vmap` can batch over stacked runs (emml/rl/packed.py). Same values within float tolerance."""
        self.dedupe = True
        """Encode each distinct instruction of a large batch once (`DEDUPE_FROM`); off where a CUDA graph captures
        the update (its shape depends on the tokens: `EmmlModel.capturable`). Same values either way."""
        if sentence:
            self.embedding = nn.Embedding(vocab_size + 1, embed_dim, padding_idx=0)
            self.gru = nn.GRU(embed_dim, gru, batch_first=True)
            self.linear = nn.Linear(gru, vocab_size)

    def bag_of_words(self, tokens: Tensor) -> Tensor:
        """x_BoW[n, i] = 1 iff word i (token id i + 1) occurs in row n."""
        # a comparison, not scatter_: exactly the same 0/1 values, and vmap batches it (scatter_ has no batching rule)
        words = torch.arange(1, self.vocab_size + 1, device=tokens.device)
        return (tokens.unsqueeze(-1) == words).any(dim=-2).to(torch.float32)

    def sentence_embedding(self, tokens: Tensor) -> Tensor:
        """x_sent = ReLU(Linear(GRU(Embedding(tokens))[last non-pad step])), or with readout 'mean' the mean of the
        GRU's outputs over the non-pad steps in place of the last one (h = 0 for an all-pad row either way); softplus
        in place of ReLU with activation 'softplus'."""
        n, length = tokens.shape
        embedded = self.embedding(tokens)
        out = gru_scan(self.gru, embedded) if self.unrolled else self.gru(embedded)[0]  # (N, L, gru)
        if self.readout == "mean":
            words = (tokens != 0).unsqueeze(-1).to(out.dtype)  # right-padded: pad steps read nothing
            return self.activation(self.linear((out * words).sum(1) / words.sum(1).clamp(min=1)))
        positions = torch.arange(1, length + 1, device=tokens.device)
        last = ((tokens != 0).long() * positions).amax(dim=1)  # 1-based; 0 = all pad
        index = (last - 1).clamp(min=0).view(n, 1, 1).expand(n, 1, out.shape[-1])
        final = out.gather(1, index).squeeze(1)
        final = final * (last > 0).unsqueeze(1).to(final.dtype)  # all-pad rows -> h = 0
        return self.activation(self.linear(final))

    def forward(self, tokens: Tensor) -> tuple[Tensor, Tensor | None]:
        """int64 tokens (N, L) -> (x_BoW (N, V), x_sent (N, V) or None)."""
        if tokens.dtype != torch.int64:
            raise TypeError(f"TextEncoder expects int64 tokens, got {tokens.dtype}")
        bow = self.bag_of_words(tokens)
        if not self.sentence:
            return bow, None
        if tokens.shape[0] >= DEDUPE_FROM and self.dedupe and not self.unrolled:  # vmap cannot batch torch.unique
            unique, inverse = torch.unique(tokens, dim=0, return_inverse=True)
            if unique.shape[0] < tokens.shape[0]:
                return bow, self.sentence_embedding(unique)[inverse]
        return bow, self.sentence_embedding(tokens)
