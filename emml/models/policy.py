"""Policy module and the shared model of "Embodied Multimodal Multitask
Learning" (Chaplot et al. 2019, arXiv 1902.01385), Section 3 ("Policy
Module") and appendix "Hyperparameters and network details".

All models share: image encoder -> fusion -> policy module. Only the fusion
unit differs between the proposed Dual-Attention model and the baselines
("we replace the proposed Dual-Attention unit ... keep everything else
identical").
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor, nn

from emml.config.schema import LABEL_CONTROLS, ModelConfig
from emml.models.encoders import ImageEncoder, TextEncoder, conv_output_size
from emml.models.fusion import FusionOutput
from emml.models.gru import gru_cell, gru_sequence
from emml.models.registry import build_fusion, check_architecture

NUM_ACTIONS = 4
"""Navigation actions (the harness's action set size)."""
NUM_TASKS = 2
"""Task indicator classes: 0 = SGN, 1 = EQA."""
FRAME_LOGITS = "frame_logits"
"""Acting state key (`EmmlModel.acting_state`): the conv logits of the K-1 frames a frame window carries."""


@dataclass
class ModelOutput:
    """Outputs of `EmmlModel.forward` for a (T, B) block of steps."""

    logits: Tensor
    """(T, B, 4) action logits of pi(a_t | I_t, T)."""
    value: Tensor
    """(T, B) value estimate V(I_t, T)."""
    answer_logits: Tensor
    """(T, B, V) pre-softmax answer scores; x_Ans = softmax(answer_logits)."""
    aux_logits: Tensor
    """(T, B, V, h, w) conv3 pre-sigmoid logits (auxiliary detection task)."""
    attention: Tensor | None
    """(T, B, h, w) spatial attention x_spat (Dual-Attention only), else None."""


def _layer_init(layer: nn.Linear, std: float) -> nn.Linear:
    """Orthogonal weights with gain `std`, zero bias (CleanRL PPO convention)."""
    nn.init.orthogonal_(layer.weight, std)
    nn.init.zeros_(layer.bias)
    return layer


class PolicyModule(nn.Module):
    """[x_S, x_Ans, time embedding, task one-hot] -> Linear+ReLU -> GRU -> pi, V.

    Section 3 "Policy Module"; hidden size 128 (appendix). The time step is a
    learned embedding over 0..max_steps (indices are clamped into that range);
    the task indicator is a one-hot of 2 and is omitted when
    ``task_indicator=False`` (the 'w/o indicator' ablation).
    """

    def __init__(
        self,
        state_dim: int,
        vocab_size: int,
        max_steps: int,
        hidden: int = 128,
        time_dim: int = 32,
        task_indicator: bool = True,
    ) -> None:
        super().__init__()
        self.max_steps = max_steps
        self.task_indicator = task_indicator
        self.time_embedding = nn.Embedding(max_steps + 1, time_dim)
        in_dim = state_dim + vocab_size + time_dim + (NUM_TASKS if task_indicator else 0)
        self.linear = nn.Linear(in_dim, hidden)
        self.gru = nn.GRUCell(hidden, hidden)
        self.unrolled = False
        """Run the GRU cell as its equations in linear ops (`emml.models.gru`), for `torch.func.vmap`."""
        self.actor = _layer_init(nn.Linear(hidden, NUM_ACTIONS), std=0.01)
        self.critic = _layer_init(nn.Linear(hidden, 1), std=1.0)

    def initial_state(self, batch_size: int, device=None) -> Tensor:
        return torch.zeros(batch_size, self.gru.hidden_size, device=device)

    def forward(
        self,
        state: Tensor,
        answer_probs: Tensor,
        time: Tensor,
        task: Tensor,
        h: Tensor,
        episode_start: Tensor,
    ) -> tuple[Tensor, Tensor, Tensor]:
        """Inputs (T, B, ...) -> logits (T, B, 4), value (T, B), final h (B, hidden).

        ``h`` is reset to zeros before every step whose ``episode_start`` is True.
        """
        t_len, batch = time.shape
        parts = [state, answer_probs, self.time_embedding(time.clamp(0, self.max_steps))]
        if self.task_indicator:
            # one-hot by comparison: F.one_hot checks its input's range on the host, which vmap cannot batch
            parts.append((task.unsqueeze(-1) == torch.arange(NUM_TASKS, device=task.device)).to(state.dtype))
        x = torch.relu(self.linear(torch.cat(parts, dim=-1)))  # batched over T*B
        keep = (~episode_start.bool()).to(x.dtype).unsqueeze(-1)  # (T, B, 1)
        if torch.is_grad_enabled() and not self.unrolled:
            out = gru_sequence(self.gru, x, h, keep)  # the loop below, with a hand-written backward
        else:  # acting, evaluation, and vmap over stacked runs (`unrolled`)
            cell = (lambda x_t, h_t: gru_cell(self.gru, x_t, h_t)) if self.unrolled else self.gru
            outs = []
            for t in range(t_len):
                h = cell(x[t], h * keep[t])
                outs.append(h)
            out = torch.stack(outs)  # (T, B, hidden)
        return self.actor(out), self.critic(out).squeeze(-1), out[-1]


class TextCache:
    """The text encoder's outputs for the token batches seen while acting, so that an instruction is encoded once
    per episode rather than at every step (the GRU over the sentence is ~20% of acting at 84×150).

    Keyed by the batch's token ids; valid for one version of the encoder's parameters (an optimizer step, a
    load_state_dict or the transfer surgery clears it). A hit returns what the encoder returned for the same
    tokens and the same weights, so outputs are bit for bit those of the uncached model (tested). Only used
    without autograd: a training forward always runs the encoder, for its gradients."""

    def __init__(self, size: int = 8) -> None:
        self.size = size
        """Token batches kept (the sampler alternates between its env groups, each with its own batch)."""
        self.entries: dict[bytes, tuple[Tensor, Tensor | None]] = {}
        self.version: tuple | None = None
        self.hits = 0
        self.misses = 0

    def __call__(self, encoder: TextEncoder, tokens: Tensor) -> tuple[Tensor, Tensor | None]:
        version = (encoder.vocab_size, *((id(p), p._version) for p in encoder.parameters()))
        if version != self.version:
            self.entries.clear()
            self.version = version
        key = str(tuple(tokens.shape)).encode() + tokens.cpu().numpy().tobytes()
        if key in self.entries:
            self.hits += 1
            return self.entries[key]
        self.misses += 1
        out = encoder(tokens)
        if len(self.entries) >= self.size:
            self.entries.pop(next(iter(self.entries)))  # the oldest batch
        self.entries[key] = out
        return out


def word_mask(words: tuple[str, ...], keep: frozenset[str]) -> Tensor:
    """(V,) 1.0 for each of `words` (in channel order) that is in `keep`, else 0.0: Eq. 1's mask of the content words
    under `ModelConfig.eq1_words` = 'content' (`EmmlModel.read_words`, emml/eval/probe_eqa.py)."""
    return torch.tensor([w in keep for w in words], dtype=torch.float32)


class EmmlModel(nn.Module):
    """Encoders + fusion unit + policy module; one class for every model.

    ``forward`` takes a (T, B) block: conv and text encoders and the fusion run
    batched over T*B; only the policy GRU loops over T. ``episode_start[t, b]``
    True resets that env's recurrent state (GRU h and PACMAN frame window)
    before step t. Returned state tensors are not detached. What the fusion
    needs is read from its declared attributes (`Fusion`: x_sent, a frame
    window), never from its class.

    A fusion with a frame window (PACMAN's `frame_window` = 'pacman_frames'):
    the window holds the last K frames, oldest first.
    State "frames" carries the previous K-1 raw uint8 frames; their conv
    features are recomputed each call (so gradients reach them in PPO replay).
    At an episode start the window is padded by repeating the episode's first
    frame (a fresh `initial_state` without an episode_start flag pads with
    black frames). Acting may carry the K-1 frames' conv logits as well
    (`acting_state`, key FRAME_LOGITS): without gradients each step then runs
    the conv stack on its new frame only, not on all K.
    """

    def __init__(self, cfg: ModelConfig, vocab_size: int, height: int, width: int, max_steps: int) -> None:
        super().__init__()
        cfg = check_architecture(cfg.validate())  # its fusion's options: their defaults where None
        if isinstance(vocab_size, bool) or not isinstance(vocab_size, int) or vocab_size < 1:
            raise ValueError(f"vocab_size={vocab_size!r} must be a positive integer")
        if isinstance(max_steps, bool) or not isinstance(max_steps, int) or max_steps < 1:
            raise ValueError(f"max_steps={max_steps!r} must be a positive integer")
        self.cfg = cfg
        self.vocab_size, self.height, self.width = vocab_size, height, width
        self.grid = conv_output_size(height, width)
        self.image_encoder = ImageEncoder(vocab_size)
        self.fusion = build_fusion(cfg, vocab_size, *self.grid)
        self.text_encoder = TextEncoder(
            vocab_size,
            cfg.embed_dim,
            cfg.gru_text,
            sentence=self.fusion.uses_sent,
            readout=cfg.sentence_readout,
            activation=cfg.sentence_activation,
        )
        self.policy = PolicyModule(
            self.fusion.state_dim,
            vocab_size,
            max_steps,
            hidden=cfg.hidden,
            time_dim=cfg.time_dim,
            task_indicator=cfg.task_indicator,
        )
        window = self.fusion.frame_window
        self.window = getattr(cfg, window) if window else 0
        """K, the frames the fusion reads (its `frame_window` field of the config); 0: the current frame only."""
        self.text_cache: TextCache | None = TextCache()
        """Acting-time cache of the instruction's encoding (None: encode at every step)."""
        self.detector: nn.Module | None = None
        """Transfer to new words (§5.4, emml/eval/transfer.py): a module mapping the observation to k extra x_I
        channels (N, k, h, w) in [0, 1], appended after the V conv3 channels; None under the paper's training."""
        self.type_gate: nn.Module | None = None
        """Control 'type_gate': the module that builds Eq. 4's gate from the dataset's word types
        (emml/models/type_gate.py; `emml.runs.rundir.load_model` attaches it, as it needs the run's words)."""

    def read_words(self, words: tuple[str, ...], content: frozenset[str]) -> EmmlModel:
        """What the model needs of the run's vocabulary (`words`, in channel order) beyond its size: under
        `ModelConfig.eq1_words` = 'content', Eq. 1's mask of the `content` words (the dataset's
        `Dataset.content_words()`). A no-op for every other model; returns ``self``."""
        if len(words) != self.vocab_size:
            raise ValueError(f"read_words: {len(words)} words for a model of {self.vocab_size} channels")
        if getattr(self.fusion, "eq1_mask", None) is not None:
            self.fusion.read_words(word_mask(words, content).to(self.fusion.eq1_mask.device))
        return self

    def at_frames(self, frames: int) -> None:
        """The frames the run has trained, told before each rollout (emml/rl/trainer.py `train_loop`): the fusion's
        schedule over them (`Fusion.at_frames`: the No Aux warm-up, `ModelConfig.answer_gate_frames`)."""
        hook = getattr(self.fusion, "at_frames", None)
        if hook is not None:
            hook(frames)

    def vmappable(self) -> EmmlModel:
        """Switch this model to the ops `torch.func.vmap` can batch over stacked copies (emml/rl/packed.py): the
        instruction GRU from linear ops, no acting cache (it keys on host values), the default memory format.
        The outputs stay those of the plain model within float tolerance (tests/rl/test_packed.py)."""
        self.text_cache = None
        self.text_encoder.unrolled = True
        self.policy.unrolled = True
        self.image_encoder.channels_last = False
        return self

    def capturable(self) -> EmmlModel:
        """Switch this model to calls a CUDA graph can capture (emml/rl/graphs.py): no host read in its forward
        (the acting cache keys on the tokens' values; the update's instruction dedupe has a shape that depends on
        them). The same outputs as the plain model (tests/rl/test_graphs.py); returns ``self``."""
        self.text_cache = None
        self.text_encoder.dedupe = False
        return self

    def trace_key(self) -> tuple:
        """The Python-level switches a captured call freezes (emml/rl/graphs.py): the conv precision and the
        fusion's own (`Fusion.trace_key`: the answer loss's warm-up). A graph is captured anew when they change."""
        return (self.image_encoder.bf16, *self.fusion.trace_key())

    @property
    def reads_labels(self) -> bool:
        """Whether acting needs the env's privileged aux labels (a diagnostic control, or detectors that read
        them); a model under the paper's protocol plays from pixels and words only."""
        return self.cfg.control in LABEL_CONTROLS or bool(getattr(self.detector, "reads_labels", False))

    def gate(self, tokens: Tensor, x_sent: Tensor | None) -> Tensor | None:
        """x_sent as the fusion reads it: the text encoder's, or under control 'type_gate' the word-type gate
        that replaces it in Eq. 4."""
        if self.cfg.control != "type_gate":
            return x_sent
        if self.type_gate is None:
            raise RuntimeError(
                "control='type_gate' needs the run's words: load the checkpoint with "
                "emml.runs.rundir.load_model(path, control='type_gate') (emml eval CKPT --control type_gate)"
            )
        return self.type_gate(tokens, x_sent)

    def sentence_gate(self, tokens: Tensor) -> Tensor | None:
        """(N, L) tokens -> the (N, V) x_sent the fusion reads (Eq. 4's gate for Dual-Attention); None for a model
        without a sentence representation."""
        _, x_sent = self.text_encoder(tokens)
        return self.gate(tokens, x_sent)

    def initial_state(self, batch_size: int, device=None) -> dict[str, Tensor]:
        """{"h": (B, hidden) zeros} (+ with a frame window, PACMAN's: {"frames": (B, K-1, 3, H, W) uint8 zeros})."""
        state = {"h": self.policy.initial_state(batch_size, device)}
        if self.window:
            state["frames"] = torch.zeros(
                batch_size,
                self.window - 1,
                3,
                self.height,
                self.width,
                dtype=torch.uint8,
                device=device,
            )
        return state

    def acting_state(self, state: dict[str, Tensor]) -> dict[str, Tensor]:
        """``state`` for acting without gradients: with a frame window, plus FRAME_LOGITS, the conv logits of its
        carried frames under the current weights, which later no-grad calls carry along instead of recomputing the
        K-1 frames' conv at every step (PACMAN acts ~K times cheaper). Valid while the weights stay: take it afresh
        after an update. Without a window, ``state`` itself."""
        if not self.window:
            return state
        frames = state["frames"]
        with torch.no_grad():
            logits = self.image_encoder(frames.flatten(0, 1)).unflatten(0, frames.shape[:2])
        return {**state, FRAME_LOGITS: logits}

    @staticmethod
    def replay_state(state: dict[str, Tensor]) -> dict[str, Tensor]:
        """``state`` without the acting cache (`acting_state`): what a rollout stores for the PPO replay, which
        recomputes the carried frames' conv so that gradients reach it."""
        return {k: v for k, v in state.items() if k != FRAME_LOGITS}

    def _window_positions(self, episode_start: Tensor) -> Tensor:
        """(T, B, K) index into the [carried K-1 frames; T new frames] sequence.

        Window slot k of step t holds frame t-(K-1)+k, clamped to the step's
        episode start (repeat the episode's first frame) when one lies inside.
        """
        t_len, batch = episode_start.shape
        k = self.window
        steps = torch.arange(t_len, device=episode_start.device)
        start_at = torch.where(episode_start.bool(), steps[:, None], -(k - 1))
        last_start = torch.cummax(start_at, dim=0).values  # (T, B); -(K-1) = none
        source = steps[:, None, None] - (k - 1) + torch.arange(k, device=steps.device)
        source = torch.maximum(source, last_start[:, :, None])  # (T, B, K) step index
        return source + (k - 1)

    def _fuse_window(self, obs, state, episode_start, x_sent):
        """The fusion over the last K frames' x_I (N, K, V, h, w) (PACMAN); the aux logits of the T new frames and
        the K-1 raw frames carried to the next call (their conv logits too under FRAME_LOGITS when ``state`` holds
        them: `acting_state`)."""
        t_len, batch = episode_start.shape
        carried = state["frames"].transpose(0, 1)  # (K-1, B, 3, H, W)
        images = torch.cat([carried, obs["image"]], dim=0)  # (T+K-1, B, 3, H, W)
        cached = state.get(FRAME_LOGITS)
        if cached is not None and not torch.is_grad_enabled():  # acting: the carried frames' conv is in the state
            new = self.image_encoder(obs["image"].flatten(0, 1)).unflatten(0, (t_len, batch))
            logits = torch.cat([cached.transpose(0, 1).to(new.dtype), new], dim=0)
        else:
            logits = self.image_encoder(images.flatten(0, 1))
            logits = logits.unflatten(0, images.shape[:2])  # (T+K-1, B, V, h, w)
        pos = self._window_positions(episode_start)  # (T, B, K)
        cols = torch.arange(batch, device=pos.device)[None, :, None]
        frames = torch.sigmoid(logits[pos, cols])  # (T, B, K, V, h, w)
        n = t_len * batch
        fused = self.fusion(frames.flatten(0, 1), None, x_sent)
        last = (pos[-1, :, 1:], torch.arange(batch, device=pos.device)[:, None])  # the K-1 frames carried on
        carry = {"frames": images[last]}
        if cached is not None:
            carry[FRAME_LOGITS] = logits[last].detach()
        aux = logits[self.window - 1 :].reshape(n, *logits.shape[2:])
        return fused, aux, carry

    def forward(
        self, obs: dict[str, Tensor], state: dict[str, Tensor], episode_start: Tensor
    ) -> tuple[ModelOutput, dict[str, Tensor]]:
        """obs["image"] uint8 (T,B,3,H,W), obs["tokens"] int64 (T,B,L),
        obs["task"] int64 (T,B), obs["time"] int64 (T,B); episode_start bool (T,B)."""
        image = obs["image"]
        t_len, batch = image.shape[:2]
        if episode_start.shape != (t_len, batch):
            raise ValueError(f"episode_start shape {tuple(episode_start.shape)} != (T, B) = {(t_len, batch)}")
        tokens = obs["tokens"].flatten(0, 1)
        if self.text_cache is not None and not torch.is_grad_enabled():  # acting: once per instruction
            x_bow, x_sent = self.text_cache(self.text_encoder, tokens)
        else:
            x_bow, x_sent = self.text_encoder(tokens)
        x_sent = self.gate(tokens, x_sent)  # diagnostic 'type_gate': Eq. 4's gate from the word types
        new_state: dict[str, Tensor] = {}
        if self.window:
            fused, aux, carry = self._fuse_window(obs, state, episode_start, x_sent)
            new_state.update(carry)
        else:
            aux = self.image_encoder(image.flatten(0, 1))  # (N, V, h, w)
            x_image = torch.sigmoid(aux) if self.cfg.x_image == "sigmoid" else torch.relu(aux)  # x_I from conv3
            if self.cfg.control == "detectors":  # diagnostic: perfect detectors
                x_image = obs["aux"].flatten(0, 1).to(x_image.dtype)
            if self.detector is not None:  # §5.4: detections of new words appended as channels of x_I
                fused = self.fusion(x_image, x_bow, x_sent, x_extra=self.detector(obs).to(x_image.dtype))
            else:
                fused = self.fusion(x_image, x_bow, x_sent)
            if self.cfg.control == "target_mask":  # diagnostic: perfect x_S, the referent's cells
                fused.state = obs["target"].flatten(0, 1).flatten(1).to(fused.state.dtype)
        fused: FusionOutput
        answer_probs = torch.softmax(fused.answer_logits, dim=-1)  # x_Ans
        logits, value, new_state["h"] = self.policy(
            fused.state.unflatten(0, (t_len, batch)),
            answer_probs.unflatten(0, (t_len, batch)),
            obs["time"],
            obs["task"],
            state["h"],
            episode_start,
        )
        attention = None if fused.attention is None else fused.attention.unflatten(0, (t_len, batch))
        out = ModelOutput(
            logits=logits,
            value=value,
            answer_logits=fused.answer_logits.unflatten(0, (t_len, batch)),
            aux_logits=aux.unflatten(0, (t_len, batch)),
            attention=attention,
        )
        return out, new_state
