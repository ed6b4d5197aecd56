"""Where SGN episodes end, per instruction (issue 33, item 3): `emml diagnose CHECKPOINT --sgn-outcomes N`.

A score below the 0.2 of walking to one of the five objects at random says that a model fails, not how. This plays
the greedy SGN episodes of `emml eval` again (the same episode seeds ``seed + i``, each drawing its instruction
uniformly in the split, so that the success rate is the evaluation's number) and records how each one ends:

* ``end`` — 'target' (the referent reached: success), 'wrong object' (another object came within `reach_distance`
  first, which ends the episode failed) or 'time-out' (``max_steps`` moves, no object reached);
* ``reached`` — the object reached: its actor name, its words ('short red torch') and its slot, its index in the
  scene (in Easy scene[i] stands at the fixed point `EASY_SLOTS[i]`; slot 2 is straight ahead of the start);
* ``matched`` — for a wrong object, the attributes it shares with the instruction: any of 'object', 'color',
  'size' (an empty list: none).

Per instruction: success rate, the shares of wrong-object ends and of time-outs, the mean episode length and the
wrong object reached most. Per split: the ends by kind; the wrong ends by shared attribute, beside what a uniform
pick among each episode's four distractors would share (``wrong_matched_chance``: an agent drawn to a partial match
exceeds it); ``reached_words`` — per word of an object (colour, object type, size), over the episodes that end at an
object, how many end at one with that word, against a uniform pick among the episode's five objects and against the
target (an agent that avoids, say, red objects ends at one less often than either); the slots reached (wrong objects
and targets apart); the success rate per instruction word.
"""

from __future__ import annotations

import dataclasses
from collections import Counter

import numpy as np
import torch

from emml.config.schema import SPLITS, DoomConfig
from emml.envs.vector import make_env
from emml.eval.diagnose_eqa import actor_words
from emml.eval.evaluate import eval_settings, play, playing
from emml.tasks.language import Dataset, describe, load_dataset

TARGET, WRONG, TIMEOUT = "target", "wrong object", "time-out"
ENDS = (TARGET, WRONG, TIMEOUT)
"""How an SGN episode ends."""
ATTRIBUTES = ("object", "color", "size")
"""The attributes an instruction can name (besides a superlative) and a wrong object can share with it."""
NONE = "none"
"""A wrong object sharing no attribute with the instruction."""


def shared_attributes(dataset: Dataset, instruction: str, name: str) -> list[str]:
    """The attributes the instruction names that actor ``name`` has: 'red tall pillar' and a short red torch share
    'color'; a superlative is not an attribute here."""
    desc, actor = describe(instruction, dataset), dataset.actors[name]
    return [a for a in ATTRIBUTES if getattr(desc, a) is not None and getattr(desc, a) == getattr(actor, a)]


def reached_index(env) -> int | None:
    """The scene index of the object within the env's reach distance, nearest first; None when none is.

    The env's own reach test (`DoomEnv._reached`) answers only whether the nearest is the target: this reads the
    same distances (a private method of the env until it exposes the reached object)."""
    dists = env._distances()
    nearest = int(np.argmin(dists))
    return nearest if dists[nearest] <= env.cfg.reach_distance else None


class EndRecorder:
    """An env (made by ``make``) that records, at the step that ends an episode, how it ended: one record per
    episode in ``log``, keyed by the episode's reset seed (each planned episode has its own)."""

    def __init__(self, env, log: dict[int, dict], dataset: Dataset):
        self.env, self.log, self.dataset = env, log, dataset
        self.seed: int | None = None
        self.steps = 0

    def reset(self, *, seed=None, options=None):
        self.seed, self.steps = seed, 0
        return self.env.reset(seed=seed, options=options)

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        self.steps += 1
        if terminated or truncated:
            self.log[self.seed] = self._record(terminated, info)
        return obs, reward, terminated, truncated, info

    def _record(self, terminated: bool, info: dict) -> dict:
        ep = self.env.episode
        text = ep.sentence.text
        reached = reached_index(self.env) if terminated else None
        if terminated and reached is None:
            raise RuntimeError(f"an SGN episode ({text!r}) terminated with no object within reach")
        if (reached == ep.target) != bool(info["success"]):
            raise RuntimeError(f"the env scored {info['success']}; object reached {reached}, target {ep.target}")
        end = TIMEOUT if reached is None else TARGET if reached == ep.target else WRONG
        name = None if reached is None else ep.scene[reached]
        return {
            "seed": self.seed,
            "instruction": text,
            "success": end == TARGET,
            "end": end,
            "steps": self.steps,
            "target": ep.scene[ep.target],
            "target_slot": ep.target,
            "scene": list(ep.scene),
            "reached": name,
            "reached_words": None if name is None else actor_words(self.dataset, name),
            "reached_slot": reached,
            "matched": shared_attributes(self.dataset, text, name) if end == WRONG else None,
        }

    def close(self):
        self.env.close()


def _share(records: list[dict], end: str) -> float:
    return float(np.mean([r["end"] == end for r in records]))


def _counts(counter: Counter) -> dict:
    return dict(sorted(counter.items(), key=lambda kv: (-kv[1], str(kv[0]))))


def _matched_chance(wrong: list[dict], dataset: Dataset) -> dict[str, float]:
    """Per attribute (and 'none'), the expected number of the ``wrong`` ends that would share it with the
    instruction if each wrong object were a uniform pick among its episode's distractors."""
    out = dict.fromkeys((*ATTRIBUTES, NONE), 0.0)
    for r in wrong:
        others = [n for i, n in enumerate(r["scene"]) if i != r["target_slot"]]
        for name in others:
            shared = shared_attributes(dataset, r["instruction"], name)
            for a in shared or [NONE]:
                out[a] += 1 / len(others)
    return {a: round(v, 2) for a, v in out.items()}


def _by_word(records: list[dict], dataset: Dataset) -> dict[str, dict]:
    """Success rate over the episodes whose instruction holds each content word (object, colour, size,
    superlative)."""
    groups = dataset.word_groups
    content = [w for g in ("objects", "colors", "sizes", "superlatives") for w in groups[g]]
    out = {}
    for w in content:
        mine = [r["success"] for r in records if w in r["instruction"].split()]
        if mine:
            out[w] = {"episodes": len(mine), "success": float(np.mean(mine))}
    return out


def _reached_words(records: list[dict], dataset: Dataset) -> dict[str, dict]:
    """Per object word, over the episodes that end at an object: how many end at an object with it ('reached'),
    the expected number under a uniform pick among the scene's objects ('uniform'), and how many targets have it."""
    ended = [r for r in records if r["reached"] is not None]
    groups = dataset.word_groups
    out = {}
    for w in (*groups["colors"], *groups["objects"], *groups["sizes"]):

        def has(name, w=w):
            return w in dataset.actors[name].words()

        out[w] = {
            "reached": sum(has(r["reached"]) for r in ended),
            "uniform": round(sum(np.mean([has(n) for n in r["scene"]]) for r in ended), 1),
            "targets": sum(has(r["target"]) for r in ended),
        }
    return out


def summarize_split(records: list[dict], dataset: Dataset) -> dict:
    """A split's figures from its episodes' records: overall, then one row per instruction played."""
    wrong = [r for r in records if r["end"] == WRONG]
    matched = Counter(a for r in wrong for a in r["matched"]) + Counter(NONE for r in wrong if not r["matched"])
    summary = {
        "episodes": len(records),
        "success": float(np.mean([r["success"] for r in records])),
        "ends": {e: sum(r["end"] == e for r in records) for e in ENDS},
        "wrong_matched": {a: matched[a] for a in (*ATTRIBUTES, NONE)},
        "wrong_matched_chance": _matched_chance(wrong, dataset),
        "reached_slots": {s: sum(r["reached_slot"] == s for r in records) for s in range(5)},
        "wrong_slots": {s: sum(r["reached_slot"] == s for r in wrong) for s in range(5)},
        "target_slots": {s: sum(r["target_slot"] == s for r in records) for s in range(5)},
        "steps": float(np.mean([r["steps"] for r in records])),
        "by_word": _by_word(records, dataset),
        "reached_words": _reached_words(records, dataset),
    }
    rows = []
    for text in dict.fromkeys(r["instruction"] for r in records):
        mine = [r for r in records if r["instruction"] == text]
        wrong_objects = Counter(r["reached_words"] for r in mine if r["end"] == WRONG)
        top = wrong_objects.most_common(1)
        rows.append(
            {
                "instruction": text,
                "episodes": len(mine),
                "success": float(np.mean([r["success"] for r in mine])),
                "wrong_object": _share(mine, WRONG),
                "time_out": _share(mine, TIMEOUT),
                "steps": float(np.mean([r["steps"] for r in mine])),
                "top_wrong": {"words": top[0][0], "count": top[0][1]} if top else None,
                "wrong_objects": _counts(wrong_objects),
            }
        )
    return {"summary": summary, "instructions": rows}


@torch.no_grad()
def diagnose_sgn(
    model,
    env_cfg: DoomConfig,
    episodes: int,
    seed: int,
    splits: tuple[str, ...] = SPLITS,
    device="cpu",
    batch: int = 8,
) -> dict:
    """The figures of the module docstring on ``episodes`` greedy SGN episodes of each split in ``splits`` that the
    run is scored on, played as `emml.eval.evaluate.evaluate` plays them (episode i: reset seed ``seed + i``)."""
    dataset = load_dataset(env_cfg.dataset)
    labels = bool(getattr(model, "reads_labels", False))  # as evaluate: only label-fed controls see the labels
    result: dict = {"model": model.cfg.name, "episodes": episodes, "seed": seed, "splits": {}}
    for task, split, instructions in eval_settings(env_cfg):
        if task != "sgn" or split not in splits:
            continue
        cfg = dataclasses.replace(
            env_cfg, tasks=task, split=split, aux_labels=labels, target_in_obs=labels, instructions=instructions
        )
        log: dict[int, dict] = {}

        def make(c, log=log):
            return EndRecorder(make_env(c), log, dataset)

        plan = [(seed + i, None) for i in range(episodes)]
        with playing(model, cfg, min(batch, episodes), make=make) as envs:
            outcomes = play(model, envs, plan, device)
        records = [log[s] for s, _ in plan]
        assert [r["success"] for r in records] == outcomes
        result["splits"][split] = {**summarize_split(records, dataset), "records": records}
    if not result["splits"]:
        result["note"] = "the run is not scored on SGN " + " or ".join(splits)
    return result


def diagnose_sgn_checkpoint(path, episodes: int, seed: int | None = None, splits=SPLITS, control=None):
    """`diagnose_sgn` on a checkpoint's model (its own config and vocabulary, ``control`` as in
    `emml.runs.rundir.load_model`), from episode seed `emml.runs.rundir.EVAL_SEED` unless told."""
    from emml.runs.rundir import EVAL_SEED, load_model

    model, cfg = load_model(path, control=control)
    return diagnose_sgn(model, cfg.env, episodes, EVAL_SEED if seed is None else seed, tuple(splits))


def sgn_table(result: dict, rows: bool = True) -> str:
    """The outcomes as text: per split a summary, then (``rows``) one line per instruction."""
    head = f"SGN outcomes of {result['model']!r}: {result['episodes']} greedy episodes per split (seeds "
    lines = [head + f"{result['seed']:,}+)"]
    if result.get("note"):
        return "\n".join(lines + [result["note"]])
    for split, data in result["splits"].items():
        s = data["summary"]
        ends = ", ".join(f"{e} {n}" for e, n in s["ends"].items())
        chance = s["wrong_matched_chance"]
        matched = ", ".join(f"{a} {n} ({chance[a]:.1f})" for a, n in s["wrong_matched"].items())
        slots = {k: " ".join(str(n) for n in s[f"{k}_slots"].values()) for k in ("reached", "wrong", "target")}
        words = ", ".join(f"{w} {v['success']:.2f}/{v['episodes']}" for w, v in s["by_word"].items())
        reached = ", ".join(
            f"{w} {v['reached']}/{v['uniform']:.0f}/{v['targets']}" for w, v in s["reached_words"].items()
        )
        lines += [
            "",
            f"{split}: success {s['success']:.3f}; ends: {ends}; mean steps {s['steps']:.1f}",
            f"  wrong object shares with the instruction (a random distractor would): {matched}",
            f"  slot 0-4 reached: {slots['reached']}; wrong objects: {slots['wrong']}; targets: {slots['target']}",
            f"  success/episodes by instruction word: {words}",
            f"  ends at an object with the word (ends/uniform pick/targets): {reached}",
        ]
        if not rows:
            continue
        width = max(len(r["instruction"]) for r in data["instructions"])
        lines.append(
            f"  {'instruction':<{width}}  {'n':>3}  {'succ':>4}  {'wrong':>5}  {'t-out':>5}  most-reached wrong"
        )
        for r in sorted(data["instructions"], key=lambda r: (r["success"], r["instruction"])):
            top = "-" if r["top_wrong"] is None else f"{r['top_wrong']['words']} ({r['top_wrong']['count']})"
            lines.append(
                f"  {r['instruction']:<{width}}  {r['episodes']:3d}  {r['success']:4.2f}  {r['wrong_object']:5.2f}  "
                f"{r['time_out']:5.2f}  {top}"
            )
    return "\n".join(lines)
