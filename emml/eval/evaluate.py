"""Greedy evaluation (§5.1, Table 2): accuracy = fraction of episodes ending in success, per task and split.

The policy acts greedily (argmax over the 4 moves; the answer word is always the argmax of x_Ans). Episodes run in
a few envs in lockstep so that the model sees batches; each (task, split) gets exactly ``episodes`` episodes, with
seeds ``seed, seed+1, …`` so that a checkpoint's numbers are reproducible.

EQA is also counted per question (issue 81): the same episodes, grouped by the question each one's reset drew, so
that a question's successes can be read beside the best fixed answer's probability for it (emml/envs/ceiling.py).
The counts of a (task, split) sum exactly to its accuracy; `Scores.questions` holds them, results.json keeps them
under "questions" and results/<table>/<profile>-questions.csv has them in long format (emml/runs/results.py).
"""

from __future__ import annotations

import dataclasses
from contextlib import contextmanager

import numpy as np
import pandas as pd
import torch

from emml.config.schema import DoomConfig
from emml.envs.vector import make_env
from emml.eval.metrics import EVALUATED, evaluated
from emml.runs.rundir import EVAL_SEED, load_model

SETTINGS = tuple((m.task, m.split) for m in EVALUATED)
"""The (task, split) pairs a run is scored on, in the order they are played: each has its declared metric, whose
column the score is written to (emml/eval/metrics.py)."""
PER_QUESTION = ("eqa",)
"""The tasks whose successes are also counted per question (`Scores.questions`)."""


class Scores(dict):
    """What `evaluate` returns: accuracy per '<task>_<split>' (the dict itself, as the trainer logs and records it)
    and, per EQA '<task>_<split>', the successes and episodes per question (`questions`)."""

    def __init__(self, accuracy: dict[str, float], questions: dict[str, dict[str, dict[str, int]]]):
        super().__init__(accuracy)
        self.questions = questions
        """{'eqa_test': {question text: {'successes': k, 'episodes': n}}}: the episodes of the accuracy, grouped by
        their question (sorted by text); a question's k over n sums, over the questions, to the setting's accuracy."""


def question_counts(sentences: list[str], outcomes: list[bool]) -> dict[str, dict[str, int]]:
    """Successes and episodes per question (sorted by text) of episodes played with these sentences."""
    if len(sentences) != len(outcomes):
        raise ValueError(f"{len(sentences)} sentences for {len(outcomes)} outcomes: one per episode is needed")
    if not outcomes:
        return {}
    frame = pd.DataFrame({"question": sentences, "success": np.asarray(outcomes, dtype=int)})
    counts = frame.groupby("question")["success"].agg(["sum", "count"])
    return {q: {"successes": int(k), "episodes": int(n)} for q, (k, n) in counts.iterrows()}


def obs_to_torch(obs: dict, device) -> dict[str, torch.Tensor]:
    """Numpy observation batch (B, ...) → tensors with a leading time axis (1, B, ...)."""
    return {k: torch.as_tensor(np.asarray(v)).to(device, non_blocking=True).unsqueeze(0) for k, v in obs.items()}


def eval_settings(env_cfg: DoomConfig) -> list[tuple[str, str, tuple[str, ...] | None]]:
    """(task, split, instructions) to evaluate: the tasks the run trains on (a single-task run is scored on its
    task only, as in Table 3), both splits; a run restricted to some sentences is scored on those only. A split
    with words outside the run's vocabulary is left out (Table 4's runs know the training instructions' words
    only: their test instructions are scored after the transfer surgery, emml/eval/transfer.py)."""
    from emml.tasks.language import load_dataset, resolve_vocabulary

    ds = load_dataset(env_cfg.dataset)
    tasks = env_cfg.played
    if not env_cfg.instructions:
        known = set(resolve_vocabulary(env_cfg.vocabulary, ds).words)
        return [
            (t, s, None)
            for t, s in SETTINGS
            if t in tasks and all(set(x.text.split()) <= known for x in ds.select(t, s))
        ]
    found = [ds.find(text) for text in env_cfg.instructions]
    out = []
    for task, split in SETTINGS:
        chosen = tuple(x.text for x in found if x.kind == task and x.split == split)
        if task in tasks and chosen:
            out.append((task, split, chosen))
    return out


@contextmanager
def playing(model, cfg: DoomConfig, n: int = 1, make=make_env):
    """The envelope of every greedy play (evaluation, diagnostics, transfer scores, figures): the model in eval
    mode and ``n`` envs of ``cfg`` (made by ``make``); on the way out, error or not, every env made is closed
    (its engine ended) and the model's mode restored."""
    was_training = model.training
    model.eval()
    envs = []
    try:
        for _ in range(n):
            envs.append(make(cfg))
        yield envs
    finally:
        for env in envs:
            env.close()
        model.train(was_training)


@torch.no_grad()
def evaluate(
    model,
    env_cfg: DoomConfig,
    episodes: int,
    seed: int = 10_000,
    device="cpu",
    batch: int = 8,
    tasks: tuple[str, ...] | None = None,
) -> Scores:
    """Accuracy per '<task>_<split>' over ``episodes`` greedy episodes each, and EQA's counts per question
    (`Scores`). ``tasks``: only these of the run's tasks (a setting's episodes do not depend on the others')."""
    if tasks is not None and not set(tasks) <= {t for t, _ in SETTINGS}:
        raise ValueError(f"tasks {sorted(set(tasks))}: allowed are {sorted({t for t, _ in SETTINGS})}")
    results, questions = {}, {}
    # the diagnostic controls (and label-fed detectors) read the privileged labels; a real model plays without them
    labels = bool(getattr(model, "reads_labels", False))
    for task, split, instructions in eval_settings(env_cfg):
        if tasks is not None and task not in tasks:
            continue
        cfg = dataclasses.replace(
            env_cfg, tasks=task, split=split, aux_labels=labels, target_in_obs=labels, instructions=instructions
        )
        sentences: list[str] = []
        with playing(model, cfg, min(batch, episodes)) as envs:
            outcomes = play(model, envs, [(seed + i, None) for i in range(episodes)], device, sentences=sentences)
        column = evaluated(task, split).name
        results[column] = float(np.mean(outcomes))
        if task in PER_QUESTION:
            questions[column] = question_counts(sentences, outcomes)
    return Scores(results, questions)


def play(
    model, envs, plan: list[tuple[int, dict | None]], device, on_step=None, sentences: list | None = None
) -> list[bool]:
    """Play the episodes of ``plan`` greedily, (reset seed, reset options) each, on ``envs`` in lockstep (an env
    takes the next planned episode when its own ends); success per planned episode, in plan order.

    ``on_step(k, env, out, i)``, when given, is called before each move of planned episode ``k`` with its env (its
    engine state is the frame the model saw), the batch's `ModelOutput` and the episode's row ``i`` in it.
    ``sentences``, when given, is filled with each planned episode's instruction or question (its reset's
    ``info['text']``), in plan order."""
    outcomes: list[bool] = [False] * len(plan)
    texts: list[str | None] = [None] * len(plan)
    envs = envs[: len(plan)]  # more envs than episodes: the rest stay idle
    started, finished = 0, 0
    obs_list, active, playing = [], [], []
    for env in envs:
        obs, info = env.reset(seed=plan[started][0], options=plan[started][1])
        obs_list.append(obs)
        texts[started] = info.get("text")
        playing.append(started)
        started += 1
        active.append(True)
    state = model.acting_state(model.initial_state(len(envs), device=device))  # weights fixed: one conv cache
    episode_start = torch.ones(1, len(envs), dtype=torch.bool, device=device)
    while finished < len(plan):
        batch = {k: np.stack([o[k] for o in obs_list]) for k in obs_list[0]}
        out, state = model(obs_to_torch(batch, device), state, episode_start)
        moves = out.logits[0].argmax(-1).cpu().numpy()
        words = out.answer_logits[0].argmax(-1).cpu().numpy()
        starts = np.zeros(len(envs), dtype=bool)
        for i, env in enumerate(envs):
            if not active[i]:
                continue
            if on_step is not None:
                on_step(playing[i], env, out, i)
            obs, _, terminated, truncated, info = env.step(np.array([moves[i], words[i]]))
            obs_list[i] = obs
            if terminated or truncated:
                finished += 1
                outcomes[playing[i]] = bool(info["success"])
                if started < len(plan):
                    obs_list[i], info = env.reset(seed=plan[started][0], options=plan[started][1])
                    texts[started] = info.get("text")
                    playing[i] = started
                    started += 1
                    starts[i] = True
                else:
                    active[i] = False
        episode_start = torch.as_tensor(starts, device=device).unsqueeze(0)
    if sentences is not None:
        sentences[:] = texts
    return outcomes


def evaluate_checkpoint(
    path,
    episodes: int,
    seed: int = EVAL_SEED,
    device: str = "cpu",
    control: str | None = None,
    tasks: tuple[str, ...] | None = None,
    compiled: bool = False,
) -> Scores:
    """Rebuild the model of a checkpoint (its own config and vocabulary) and evaluate it greedily over ``episodes``
    per (task, split) from episode seed ``seed`` (`evaluate`, ``tasks`` as there); ``control`` as in `load_model`
    (emml.runs.rundir). ``compiled``: its conv stack and fusion unit through `torch.compile`, as the trainer runs them
    under `TrainConfig.compile` (emml/models/compiled.py): the same model within float tolerance, whose greedy argmax
    can still follow the last bits near a tie (emml/eval/rescore.py, `rescore_questions`)."""
    model, cfg = load_model(path, device, control)
    if compiled:
        from emml.models.compiled import compile_model

        compile_model(model)
    torch.manual_seed(seed)
    return evaluate(model, cfg.env, episodes, seed=seed, device=device, tasks=tasks)
