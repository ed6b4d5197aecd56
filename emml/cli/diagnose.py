"""Why a model does what it does: `emml diagnose` and `emml probe-eqa` (emml/eval/)."""

from __future__ import annotations

from pathlib import Path
from typing import Literal

import typer

from emml.cli.common import (
    _CONTROLS,
    JSON_HELP,
    SPLITS_OR_BOTH,
    Activation,
    Control,
    Eq1Words,
    Splits,
    _check_checkpoint,
    _echo,
    _fail,
    _own_engines,
)


def diagnose(
    checkpoint: Path = typer.Argument(..., help="A run's checkpoint.pt."),
    episodes: int = typer.Option(
        20, min=0, help="Sampled SGN episodes for the attention and detector figures (0: no SGN figures)."
    ),
    step0_episodes: int = typer.Option(100, min=0, help="Resets for the actor's sensitivity to the target slot."),
    eqa_episodes: int = typer.Option(10, min=0, help="Greedy episodes per EQA question (0: no EQA table)."),
    sgn_outcomes: int = typer.Option(
        0, min=0, help="Greedy SGN episodes per split, seeded as `emml eval`: how each ends, per instruction (0: none)."
    ),
    split: Splits = typer.Option("both", help="The SGN splits of --sgn-outcomes."),
    control: Control | None = typer.Option(None, help="Play under a diagnostic control: " + _CONTROLS + "."),
    seed: int = typer.Option(20_000, help="Seed of the first episode (episode i plays seed + i)."),
    gate: bool = typer.Option(
        False,
        "--gate",
        help="Only the GA2 gate on the EQA test questions whose subject is unseen (no engine; every other figure "
        "left out): its mass on the answer's attribute and the answer channels it shuts.",
    ),
    record: bool = typer.Option(
        False, "--record", help="With --gate: append its diag/gate_* figures to the finished run's metrics.csv."
    ),
    as_json: bool = typer.Option(False, "--json", help=JSON_HELP),
):
    """Why a model does or does not follow instructions.

    SGN: how often the attention lands on the target, each word detector's average precision, how much the first
    move depends on where the target stands, and whether x_I collapsed to a constant code. EQA, per question: its
    accuracy, answers, where the attention sits and the GA2 gate per channel. With --sgn-outcomes, per SGN
    instruction: its success and how its episodes end (target, which wrong object, time-out). With --gate, only the GA2
    gate on the EQA test questions whose subject no training question names (no engine), and with --record
    its diag/gate_* figures appended to the finished run's metrics.csv at its last frame."""
    from emml.eval.diagnose import diagnose_checkpoint, summary_line
    from emml.eval.diagnose_eqa import eqa_table
    from emml.eval.diagnose_sgn import diagnose_sgn_checkpoint, sgn_table
    from emml.tasks.language import SPLITS, check_choice

    _check_checkpoint(checkpoint)
    if record and not gate:
        _fail("--record appends the gate figures: only with --gate")
    if gate:
        return _gate(checkpoint, record, as_json)
    _own_engines()
    try:
        check_choice("split", split, SPLITS_OR_BOTH)
        result = diagnose_checkpoint(checkpoint, episodes, step0_episodes, seed, eqa_episodes, control)
        if sgn_outcomes:
            splits = SPLITS if split == "both" else (split,)
            result["sgn_outcomes"] = diagnose_sgn_checkpoint(checkpoint, sgn_outcomes, splits=splits, control=control)
    except ValueError as e:  # a control the model cannot take, a split that is not one
        _fail(str(e))
    lines = []
    if episodes:
        ap = sorted(result["detector_ap_words"].items(), key=lambda x: -x[1])
        slots = "; ".join(f"slot {s}: " + " ".join(f"{p:.2f}" for p in m) for s, m in result["step0_moves"].items())
        lines += [
            summary_line(result) + f" ({result['frames']} frames)",
            "detector AP per word: " + ", ".join(f"{w} {v:.2f}" for w, v in ap),
            _saturation_line(result),
            "step-0 move distribution (forward left right answer) by target slot: "
            + (slots or _no_step0(step0_episodes)),
        ]
    if result["conv3_one_way"] is not None:
        lines.append(
            f"conv3 since its init: {result['conv3_one_way']:.0%} of a channel's weights moved one way (median; 50%: "
            f"no common direction), weight sum moved {result['conv3_shift']:.2f} (median |sum|)"
        )
    if "eqa" in result:
        lines += ([""] if lines else []) + [eqa_table(result["eqa"])]
    if "sgn_outcomes" in result:
        lines += ([""] if lines else []) + [sgn_table(result["sgn_outcomes"])]
    _echo(result, as_json, "\n".join(lines))


def _gate(checkpoint: Path, record: bool, as_json: bool) -> None:
    """`emml diagnose --gate [--record]`: the question gate's figures (emml/eval/diagnose_gate.py), read from the
    checkpoint's x_sent alone; with ``record``, appended to the finished run's metrics.csv at its last frame."""
    from emml.eval.diagnose_gate import diagnose_gate, gate_table, record_gate
    from emml.runs.rundir import load_model
    from emml.runs.runlock import RunLocked

    try:
        if record:
            out = record_gate(checkpoint.parent)
            result = out["result"]
        else:
            model, cfg = load_model(checkpoint)
            result = diagnose_gate(model, cfg.env)
    except (ValueError, RunLocked) as e:  # a run not finished, a run being trained
        _fail(str(e))
    text = gate_table(result)
    if record:
        written = out["written"]
        text += f"\n{checkpoint.parent / 'metrics.csv'}: " + (
            f"{len(written)} figures appended at frame {out['frames']:,} ({', '.join(written)})"
            if written
            else f"nothing appended (the figures are there at frame {out['frames']:,}, or the model has none)"
        )
        result = {**result, "recorded": {k: out[k] for k in ("frames", "figures", "written")}}
    _echo(result, as_json, text)


def _saturation_line(result: dict) -> str:
    """x_I's saturation (emml.eval.diagnose.x_image_saturation): how many of the channels counted are pinned, and
    which; the words counted (an Aux run's all-zero labels train their channels to 0: not a collapse, issue 61)."""
    from emml.eval.diagnose import counted_words

    channels = result["x_image_channels"]
    counted = [w for w, c in channels.items() if c.get("counted", True)]
    pinned = [w for w in counted if channels[w]["pinned"]]
    return (
        f"x_I saturation: {len(pinned)}/{len(counted)} channels counted pinned on every cell"
        + (f" ({', '.join(pinned)})" if pinned else "")
        + f"; counted: {counted_words(result)}"
        + f"; spatial std of x_I {result['x_image_spatial_std']:.3f} over them (per channel: "
        + ", ".join(f"{w} {c['spatial_std']:.3f}" for w, c in channels.items())
        + ")"
    )


def _no_step0(step0_episodes: int) -> str:
    """Why the step-0 figures are missing: none asked for, or a difficulty whose spawn is not fixed (Hard)."""
    return "n/a (--step0-episodes 0)" if not step0_episodes else "n/a (the spawn is not fixed: Hard)"


def probe_eqa_cmd(
    checkpoint: Path = typer.Argument(..., help="A run's checkpoint.pt (Dual-Attention with its GA2 gate, on EQA)."),
    episodes: int = typer.Option(40, help="First frames per question (seeds 30,000+)."),
    readouts: str = typer.Option("last,mean", help="x_sent readouts to train, comma-separated: last | mean."),
    seeds: int = typer.Option(3, help="Encoders trained per readout (seeds 0, 1, ...)."),
    steps: int = typer.Option(600, help="Adam steps per encoder (minibatches of --batch frames)."),
    batch: int = typer.Option(128, help="Frames per minibatch."),
    lr: float = typer.Option(3e-3, help="Adam's learning rate."),
    eq1_words: Eq1Words = typer.Option(
        "all", help="Words Eq. 1 sums the channels of: all (as the model) or content (function words left out)."
    ),
    init: Literal["checkpoint", "fresh"] = typer.Option(
        "checkpoint", help="Where the retrained GRU and Linear start: the checkpoint's weights or a fresh draw."
    ),
    activation: Activation = typer.Option("relu", help="x_sent's activation on the retrained Linear."),
    as_json: bool = typer.Option(False, "--json", help=JSON_HELP),
):
    """Would another question encoder answer the EQA test questions?

    On the first frames of EQA episodes, with the conv and the Dual-Attention unit frozen, x_sent's encoder (GRU
    and Linear; the embedding the checkpoint's, frozen) is retrained on the training questions' answers per readout
    and seed; its answer accuracy on the train and test questions is shown beside the checkpoint's own encoder."""
    from emml.eval.probe_eqa import ProbeOptions, probe_checkpoint, probe_table

    chosen = tuple(r.strip() for r in readouts.split(",") if r.strip())
    try:
        options = ProbeOptions(
            episodes, chosen, seeds, steps, batch, lr, eq1_words=eq1_words, init=init, activation=activation
        ).validate()
    except ValueError as e:
        _fail(str(e))
    _check_checkpoint(checkpoint)
    _own_engines()
    if not as_json:
        typer.echo(f"probing {checkpoint}: {episodes} first frames per EQA question…", err=True)
    try:
        result = probe_checkpoint(checkpoint, options)
    except ValueError as e:  # a model without a GA2 gate, a run not scored on EQA
        _fail(str(e))
    _echo(result, as_json, probe_table(result))
