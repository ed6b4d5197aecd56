"""The run's configs: `TrainConfig` (one training run) and `PPOConfig`, and the configs' one import point: the
environment configs (env.py), the model's (model.py), how a model option is declared and checked
(model_options.py), the shared value checks (checks.py) and `--set` overrides (overrides.py) are importable from
here, as callers import them. Every field has a docstring with its unit and source (paper section, or 'our choice'
with the reason, collected in docs/fidelity.md). `validate()` fails before any compute with the field's name and the
allowed values.

Configs are leaves: emml/config imports no other layer of `emml`. What needs more than the values is checked where
training starts, not here (`emml.rl.hardware.check_runnable`): the model registry (plugins loaded) names the model
and checks the options its fusion declares (`model_option`, `emml.models.Fusion.options`); the machine runs
`compile` (a C++ compiler), `precision` (native bf16) and `device` (CUDA)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Annotated, ClassVar, Literal

from pydantic import Field

from emml.config.checks import (
    MAX_FRAMES,
    PLAIN_NAME,
    Count,
    Envs,
    Episodes,
    Epochs,
    Folder,
    Fraction,
    Frames,
    LearningRate,
    PlainName,
    Positive,
    PositiveNumber,
    Threads,
    Weight,
    check,
    check_choice,
    config_from_dict,
)
from emml.config.env import (
    ENV_CONFIGS,
    ENV_DIFFICULTIES,
    RESOLUTIONS_16_9,
    SPLITS,
    TASK_CHOICES,
    TASKS,
    VOCABULARY_SOURCES,
    DoomConfig,
    HouseConfig,
    env_config_class,
    match_env_class,
)
from emml.config.model import (
    ACTIVATIONS,
    ANSWER_GRADS,
    CONTROLS,
    EQ1_WORDS,
    LABEL_CONTROLS,
    SENTENCE_READOUTS,
    SHARED_MODEL_OPTIONS,
    X_IMAGES,
    ModelConfig,
)
from emml.config.model_options import CHOICES, NAME_PART, check_model_options, model_option, option_fields
from emml.config.overrides import apply_overrides

__all__ = [  # the configs' one import point: what is defined here, and the names of the rooms below it
    "COMPILE",
    "PRECISIONS",
    "DEVICES",
    "check_device_name",
    "AUX_BALANCES",
    "PPOConfig",
    "TrainConfig",
    "MAX_FRAMES",
    "PLAIN_NAME",
    "check",
    "check_choice",
    "config_from_dict",
    "ENV_CONFIGS",
    "ENV_DIFFICULTIES",
    "RESOLUTIONS_16_9",
    "SPLITS",
    "TASK_CHOICES",
    "TASKS",
    "VOCABULARY_SOURCES",
    "DoomConfig",
    "HouseConfig",
    "env_config_class",
    "match_env_class",
    "ACTIVATIONS",
    "ANSWER_GRADS",
    "CONTROLS",
    "EQ1_WORDS",
    "LABEL_CONTROLS",
    "SENTENCE_READOUTS",
    "SHARED_MODEL_OPTIONS",
    "X_IMAGES",
    "ModelConfig",
    "CHOICES",
    "NAME_PART",
    "check_model_options",
    "model_option",
    "option_fields",
    "apply_overrides",
]

COMPILE = ("off", "on", "auto")
"""Values of TrainConfig.compile (emml/models/compiled.py)."""

PRECISIONS = ("fp32", "bf16")
"""Values of TrainConfig.precision (emml/rl/precision.py)."""

DEVICES: tuple[str, ...] = ("cpu", "cuda")
"""Kinds of `TrainConfig.device` ('cuda' may name a GPU: 'cuda:1')."""


def check_device_name(device: str) -> None:
    """Raise a ValueError naming the field 'device' and its allowed kinds (whether the machine has it is
    `emml.rl.hardware.check_device`)."""
    check_choice("device", device.split(":")[0], DEVICES)


AUX_BALANCES: tuple[str, ...] = ("none", "word")
"""Values of `PPOConfig.aux_balance`: the aux cross-entropy averaged over every cell (the paper's), or balanced per
word between the cells labelled 1 and those labelled 0."""


@dataclass
class PPOConfig:
    """Hyper-parameters of the PPO update (paper appendix A unless noted)."""

    clip_coef: Annotated[PositiveNumber, Field(lt=1), "a number in (0, 1)"] = 0.2
    """Surrogate clipping epsilon (PPO Eq. 7). Paper: 0.2."""
    gamma: Fraction = 0.99
    """Discount factor. Paper: 0.99."""
    gae_lambda: Fraction = 0.95
    """GAE lambda (Schulman et al. 2016). Paper silent -- our choice (PPO paper's Atari value)."""
    epochs: Epochs = 4
    """Optimisation epochs per rollout. Paper: 4."""
    minibatches: Positive = 1
    """Minibatches per epoch, split along the env axis so recurrent sequences stay whole. Paper: 1 ("single batch")."""
    lr: LearningRate = 2.5e-4
    """Adam learning rate. Paper: 2.5e-4 (constant; no annealing mentioned)."""
    ent_coef: Weight = 0.01
    """Entropy-bonus coefficient on the move distribution. Paper silent -- our choice (PPO paper's Atari value)."""
    vf_coef: Weight = 0.5
    """Value-loss coefficient (value loss is 0.5 * MSE). Paper silent -- our choice (CleanRL default)."""
    max_grad_norm: PositiveNumber = 0.5
    """Global gradient-norm clip. Paper silent -- our choice (CleanRL default)."""
    norm_adv: bool = True
    """Normalise advantages per minibatch to zero mean / unit std. Paper silent -- our choice (CleanRL default)."""
    clip_vloss: bool = False
    """Use PPO2-style clipped value loss. Paper silent -- our choice (off; Andrychowicz et al. 2021: no benefit)."""
    answer_coef: Weight = 1.0
    """Weight of the supervised answer cross-entropy. Paper silent on the weight -- our choice."""
    aux_coef: Weight = 1.0
    """Weight of the spatial auxiliary binary cross-entropy. Paper silent on the weight -- our choice."""
    aux_balance: Literal[AUX_BALANCES] = "none"
    """How the aux cross-entropy weighs a word's cells (`AUX_BALANCES`): "none", the mean over every cell (the paper:
    'trained with cross-entropy loss', 'Auxiliary Task'), or "word" (opt-in), per word the mean over the cells
    labelled 1 and the mean over those labelled 0, halved: a small object's few cells weigh as much as the rest of
    the frame. Retraining a checkpoint's conv on the aux labels alone, it learned the keys no better than the plain
    mean (docs/fidelity.md, "The aux loss's weighting is not what holds them back")."""
    adam_eps: PositiveNumber = 1e-5
    """Adam epsilon. Paper silent -- our choice (CleanRL/baselines PPO value)."""

    def validate(self) -> PPOConfig:
        """Raise ValueError naming the first out-of-range field; return self."""
        return check(self, "PPOConfig.")


@dataclass
class TrainConfig:
    """One training run: environment, model, PPO and the run's own settings (issue: one trainer for all tables).

    Defaults are the paper's protocol (Appendix A); profiles in reproduce/profiles.toml change cost, not
    protocol, and every report states its profile."""

    model: Annotated[PlainName, "a model registry name (`emml models`)"] = "dual_attention"
    """Registry name of the model (`emml models`), ablations included."""
    aux: bool = False
    """Train with the auxiliary detection task (§3.2); turns on the env's aux labels."""
    seed: Count = 0
    """Seeds Python, NumPy, torch and the envs (worker i gets seed + i)."""
    frames: Frames = 10_000_000
    """Agent steps to train, summed over actors (§5.1: 10M Easy, 50M Hard); at least one update (num_envs ×
    num_steps), and rounded up to whole updates (10M is 9,766 updates of 1,024: 10,000,384 frames)."""
    num_envs: Envs = 8
    """Parallel actors (Appendix A: 8)."""
    num_steps: Positive = 128
    """Rollout horizon per actor and update (Appendix A: 128)."""
    profile: PlainName = "paper"
    """Name of the profile the run came from (smoke, demo, quick, paper), recorded everywhere."""
    eval_every: Frames = 0
    """Evaluate every this many frames for the curves; 0: only at the end."""
    eval_episodes: Episodes = 100
    """Greedy evaluation episodes per (task, split) of the evaluations during training (the curves)."""
    final_eval_episodes: Episodes = 500
    """Greedy evaluation episodes per (task, split) of the final evaluation, the score in results.json and the
    results table (paper silent). Larger than `eval_episodes`: one checkpoint's SGN train accuracy (GA quick seed
    0) ranged 0.51-0.71 over 18 disjoint blocks of 100 episodes, 0.54-0.61 over 5 blocks of 500 (docs/fidelity.md,
    "Trainer"); a score's binomial sd is ≤ 0.05 at 100 episodes, ≤ 0.022 at 500."""
    score: bool = True
    """Play the final evaluation and record the run's score (results.json, its results row). False: a measurement
    run (`emml bench train`'s temporary runs), trained and checkpointed only; an untrained agent's evaluation
    episodes run to the time limit and were most of a smoke bench's time."""
    diagnose_episodes: Count = 20
    """SGN episodes behind the diagnostics logged at every evaluation (attention on target, detector AP; the actor's
    sensitivity reads 5× as many first steps: emml/eval/diagnose.py); 0: none."""
    checkpoint_every: Positive = 10
    """Write the checkpoint every this many updates (and at the end)."""
    log_every: Positive = 10
    """A log line every this many updates (metrics go to MLflow every update)."""
    answer_supervision: Literal["eqa_steps", "answer_steps"] = "eqa_steps"
    """Which steps train the answer cross-entropy: 'eqa_steps' (every step of an EQA episode: the correct answer
    is fixed for the episode) or 'answer_steps' (only steps where the agent answered). Paper silent."""
    device: str = "cpu"
    """'cpu' or 'cuda'."""
    precision: Literal[PRECISIONS] = "fp32"
    """'fp32' (the paper's) or 'bf16': the conv stack's convolutions in bf16 in acting and the PPO update; the rest
    of the model, weights, losses and evaluation in fp32 (emml/rl/precision.py). bf16 is refused on a CPU
    without native bf16 arithmetic, where it runs slower."""
    compile: Literal[COMPILE] = "off"
    """torch.compile the conv stack and the fusion unit (emml/models/compiled.py): the same model within float
    tolerance, ~10-20 s of compiling at start, then faster (2-core CPU, end to end: x1.03 at 84x150, x1.23 at
    168x300; docs/throughput.md). 'on' (refused before any compute where it cannot run: a CPU without a C++
    compiler), 'off', or 'auto' (on where measured faster: a CPU with a C++ compiler; off on CUDA until measured
    there)."""
    cuda_graphs: bool = False
    """Acting and the PPO update replayed as CUDA graphs (emml/rl/graphs.py): the same computation, launched as one
    graph instead of hundreds of kernels per call. The paper's single batch only (`ppo.minibatches` = 1). On a CPU
    the same fixed-tensor calls run uncaptured (no faster; what the CPU tests compare with the plain path). Off by
    default until measured on a GPU (docs/throughput.md)."""
    threads: Threads = 0
    """torch threads; 0: all cores (the learner and the env workers take turns, PPO being synchronous)."""
    asynchronous: bool = True
    """Env workers in processes (True) or in the learner process (False, for debugging)."""
    env_groups: int = 2
    """Actors are stepped in this many groups, in turn: one group simulates while the policy acts for the next
    (double-buffered sampling; same algorithm, see emml/rl/sampler.py). 1: all actors in lockstep. Must divide
    num_envs."""
    envs_per_worker: int = 1
    """Envs hosted by each env worker process, stepped at once from one thread each (ViZDoom releases the GIL;
    `emml.envs.vector.GroupedDoomVectorEnv`): the same envs and seeds, fewer processes to wake at every step.
    Must divide num_envs / env_groups."""
    acting_threads: Threads = 1
    """torch threads while acting (batches of num_envs/env_groups, one step): one is about as fast as two for
    such small batches and leaves the other cores to the env workers; 0: as many as the learner."""
    max_engine_restarts: Count = 3
    """An env worker restarts its engine when it dies (the episode in flight is dropped and counted); this many
    deaths in a row, less than `engine_restart_window` steps apart, end the run with an EngineError."""
    engine_restart_window: Count = 1000
    """Steps of a worker after which an engine death no longer counts as repeated."""
    table: PlainName = "adhoc"
    """MLflow experiment / results table the run belongs to."""
    run_root: Folder = "runs"
    """Where run directories (checkpoints, results.json) go, relative to the project root unless absolute."""
    results_root: Folder = "results"
    """Where finished runs are recorded as rows of `<table>/<profile>.csv` (small, committed), relative to the
    project root unless absolute."""
    env: DoomConfig = field(default_factory=DoomConfig)
    """The environment (its aux_labels follows `aux`): a HouseConfig when its difficulty is 'house'."""
    ppo: PPOConfig = field(default_factory=PPOConfig)
    """The PPO update's hyper-parameters (the paper's defaults)."""
    model_options: Annotated[dict, "a table of model option names to values"] = field(default_factory=dict)
    """Overrides of the model's options: those every model shares (`ModelConfig`) and those its fusion declares
    (`emml.models.Fusion.options`); checked against the model's declared options where training starts
    (`emml.rl.hardware.check_runnable`, `emml.models.model_config`), before any compute."""

    RUNTIME: ClassVar[tuple[str, ...]] = (
        "frames",  # asking for more frames continues a run (finished or not) to the new target
        "eval_every",
        "eval_episodes",  # how a run is measured, not what it is: the evaluations' size
        "final_eval_episodes",
        "score",
        "diagnose_episodes",
        "checkpoint_every",
        "log_every",
        "threads",
        "asynchronous",
        "env_groups",  # how the actors are stepped, not what they do
        "envs_per_worker",
        "acting_threads",
        "max_engine_restarts",
        "engine_restart_window",
        "device",
        "compile",
        "cuda_graphs",
        "run_root",
        "results_root",
    )
    """How a run runs, not what it is: every other field is its identity (`identity`, emml/runs/rundir.py), which names
    its run dir and must match for a rerun to resume it."""

    def __post_init__(self):
        if self.ppo is None:  # callers that passed None for the defaults
            self.ppo = PPOConfig()
        self.env.aux_labels = self.aux

    def validate(self) -> TrainConfig:
        """The fields' values, before any compute. The model's registry entry and this machine are checked where
        training starts (`emml.rl.hardware.check_runnable`)."""
        check(self)
        for key in self.model_options:
            if not isinstance(key, str) or not key.isidentifier() or key in ("name", "options"):
                raise ValueError(
                    f"model_options: {key!r} is not a model option name; the options every model shares: "
                    + ", ".join(SHARED_MODEL_OPTIONS)
                    + " (and its fusion's own, `emml models`)"
                )
        check_choice("env.difficulty", self.env.difficulty, ENV_DIFFICULTIES)
        self.env.validate()
        self.ppo.validate()
        check_device_name(self.device)
        if "answer_gate_frames" in self.model_options:  # here too: it names the run dir (warm<N>), made after this
            warm = ModelConfig(answer_gate_frames=self.model_options["answer_gate_frames"])
            check(warm, "model_options.", ("answer_gate_frames",))
        if self.frames < self.frames_per_update:  # it used to be rounded up to one update, silently
            raise ValueError(
                f"frames={self.frames!r} is less than one update (num_envs × num_steps = {self.frames_per_update}); "
                f"the minimum is {self.frames_per_update}"
            )
        if self.env_groups < 1 or self.num_envs % self.env_groups:
            raise ValueError(f"env_groups={self.env_groups!r} must be a positive divisor of num_envs={self.num_envs}")
        group = self.num_envs // self.env_groups
        if self.envs_per_worker < 1 or group % self.envs_per_worker:
            k = self.envs_per_worker
            raise ValueError(f"envs_per_worker={k!r} must be a positive divisor of num_envs / env_groups = {group}")
        if self.cuda_graphs and self.ppo.minibatches != 1:
            raise ValueError(
                f"cuda_graphs=true captures the paper's single batch: it needs ppo.minibatches=1, "
                f"got {self.ppo.minibatches} (or set cuda_graphs=false)"
            )
        if self.cuda_graphs and self.compile == "on" and self.device.startswith("cuda"):
            raise ValueError("cuda_graphs=true with compile='on' on CUDA is not measured: use compile='off' or 'auto'")
        control = self.model_options.get("control", "none")
        if control == "type_gate":
            raise ValueError(
                "model_options.control='type_gate' is an evaluation control: apply it to a trained checkpoint "
                "(emml eval CKPT --control type_gate, emml diagnose CKPT --control type_gate)"
            )
        if control != "none" and not self.aux:
            raise ValueError(f"model_options.control={control!r} reads the aux labels: it needs aux=True")
        return self

    @property
    def frames_per_update(self) -> int:
        """Derived: num_envs × num_steps (1,024 under the paper's protocol)."""
        return self.num_envs * self.num_steps

    @property
    def num_updates(self) -> int:
        """Derived: updates to reach `frames` (rounded up)."""
        return -(-self.frames // self.frames_per_update)

    def identity(self) -> dict:
        """`to_dict` less the `RUNTIME` fields: what the run is (emml/runs/rundir.py names and resumes runs by it)."""
        return {k: v for k, v in self.to_dict().items() if k not in self.RUNTIME}

    def to_dict(self) -> dict:
        d = asdict(self)
        d["ppo"] = asdict(self.ppo)
        return d

    @classmethod
    def from_dict(cls, values: dict) -> TrainConfig:
        """Inverse of to_dict (unknown keys are rejected by name)."""
        values = dict(values)
        env_values = values.pop("env", {})
        env = config_from_dict(env_config_class(env_values.get("difficulty", "easy")), env_values)
        ppo = config_from_dict(PPOConfig, values.pop("ppo", {}) or {})
        cfg = config_from_dict(cls, {k: v for k, v in values.items()})
        cfg.env, cfg.ppo = env, ppo
        cfg.env.aux_labels = cfg.aux
        return cfg
