"""The paper's figures from a smoke checkpoint: the right panels, and the plotted arrays are the model's own."""

import numpy as np
import pytest
import torch
from PIL import Image, ImageSequence
from typer.testing import CliRunner

from emml.cli import app
from emml.config.profiles import profile_config
from emml.eval.evaluate import obs_to_torch
from emml.report.savefig import PAGE_INCHES, outside
from emml.report.visualize import CHANNEL_WORDS, attention_figure, channels_figure, episode_gif, record_episode
from emml.rl.trainer import train
from emml.runs.rundir import CHECKPOINT, load_model


@pytest.fixture(scope="module")
def checkpoints(tmp_path_factory):
    """A smoke Dual-Attention checkpoint with aux and one without (64 frames each)."""
    import os

    root = tmp_path_factory.mktemp("vis")
    os.environ["MLFLOW_TRACKING_URI"] = f"sqlite:///{root}/mlflow.db"
    out = {}
    for aux in (True, False):
        over = {
            "run_root": str(root / "runs"),
            "results_root": str(root / "results"),
            "table": "vis",
            "frames": 64,
            "eval_episodes": 1,
            "diagnose_episodes": 0,
            "env.max_steps": 12,
        }
        out[aux] = train(profile_config("smoke", "easy", over, aux=aux), quiet=True).run_dir / CHECKPOINT
    del os.environ["MLFLOW_TRACKING_URI"]
    return out


def test_the_recorded_episode_is_the_models_own_output(checkpoints, no_leftovers):
    model, cfg = load_model(checkpoints[True])
    ep = record_episode(model, cfg.env, "sgn", seed=3)
    assert 1 <= len(ep.frames) <= 12 and len(ep.attention) == len(ep.answers) == len(ep.channels) == len(ep.frames)
    # replay the recorded frames through the model: the same x_spat, x_Ans and conv3 channels, step by step
    state = model.initial_state(1)
    for t, frame in enumerate(ep.frames):
        obs = {"image": frame.transpose(2, 0, 1), "tokens": ep.tokens, "task": 0, "time": t}
        out, state = model(
            obs_to_torch({k: np.asarray(v)[None] for k, v in obs.items()}, "cpu"), state, torch.tensor([[t == 0]])
        )
        np.testing.assert_allclose(ep.attention[t], out.attention[0, 0].detach().numpy(), rtol=1e-5, atol=1e-6)
        np.testing.assert_allclose(
            ep.answers[t], torch.softmax(out.answer_logits[0, 0], -1).detach().numpy(), rtol=1e-5, atol=1e-6
        )
        assert int(out.logits[0, 0].argmax()) == ep.moves[t]
    words = ep.sentence.split()
    assert set(w for w in words if w in ep.words) <= set(ep.words)


def _panels(fig) -> list:
    """A figure's panels, its colour scales left out."""
    return [ax for ax in fig.axes if ax.get_label() != "<colorbar>"]


def test_the_attention_figure_has_a_row_per_step_with_the_models_arrays(checkpoints, tmp_path, no_leftovers):
    model, cfg = load_model(checkpoints[True])
    ep = record_episode(model, cfg.env, "eqa", seed=1)
    fig = attention_figure(ep, tmp_path / "a.png", rows=3)
    steps = min(3, len(ep.frames))
    panels = _panels(fig)
    assert len(panels) == 1 + 3 * steps and (tmp_path / "a.png").stat().st_size > 0
    assert len(fig.axes) > len(panels)  # the maps carry a colour scale
    overlay = panels[2].get_images()[1].get_array()  # first step row: frame, then frame + x_spat
    np.testing.assert_array_equal(np.asarray(overlay), ep.attention[0])
    assert "EQA" in fig.axes[0].get_title()
    assert fig.get_size_inches()[0] == PAGE_INCHES and outside(fig) == []  # at its print width, no text cut off
    # the top panel: x_sent on every vocabulary channel, labelled, with the model's values (Eq. 4's gate)
    bars = fig.axes[0].patches
    assert len(bars) == len(ep.words) == model.vocab_size
    assert [t.get_text() for t in fig.axes[0].get_xticklabels()] == list(ep.words)
    x_sent = model.sentence_gate(torch.as_tensor(ep.tokens)[None])[0].detach().numpy()
    np.testing.assert_allclose([b.get_height() for b in bars], x_sent, rtol=1e-6)


def test_the_channel_figure_compares_aux_and_no_aux_channels(checkpoints, tmp_path, no_leftovers):
    models = [("aux", load_model(checkpoints[True])[0]), ("no aux", load_model(checkpoints[False])[0])]
    cfg = load_model(checkpoints[True])[1]
    fig, labels, channels = channels_figure(models, cfg.env, tmp_path / "c.png")
    axes = np.array(_panels(fig)).reshape(len(CHANNEL_WORDS), 4)
    assert [ax.get_title() for ax in axes[0]] == ["aux label", "aux", "no aux", "frame"]
    assert [ax.get_ylabel() for ax in axes[:, 0]] == list(CHANNEL_WORDS)
    v = list(cfg.env.vocabulary).index("red")  # the plotted channel is the model's sigmoid(conv3) for the word
    np.testing.assert_array_equal(np.asarray(axes[0, 1].get_images()[0].get_array()), channels["aux"][v])
    np.testing.assert_array_equal(np.asarray(axes[0, 0].get_images()[0].get_array()), labels[v])
    assert not np.array_equal(channels["aux"], channels["no aux"])  # two models, two columns
    assert fig.get_size_inches()[0] == PAGE_INCHES and outside(fig) == []  # at its print width, no text cut off


def test_the_channel_figure_leaves_out_words_the_run_does_not_know(checkpoints, tmp_path, no_leftovers):
    """A run on the training vocabulary (Table 4) has no 'red' or 'pillar' channel: those rows are left out, not
    an error (`make reports` failed on the Table 4 quick run)."""
    model, cfg = load_model(checkpoints[True])
    fig, _, _ = channels_figure([("aux", model)], cfg.env, tmp_path / "c.png", words=("red", "unseenword"))
    assert [ax.get_ylabel() for ax in np.array(_panels(fig)).reshape(-1, 3)[:, 0]] == ["red"]


def test_cli_figures_and_videos(checkpoints, tmp_path, no_leftovers):
    runner = CliRunner()
    ck = str(checkpoints[True])
    r = runner.invoke(app, ["visualize", "channels", ck, "--compare", str(checkpoints[False]), "--out", str(tmp_path)])
    assert r.exit_code == 0, r.output
    r = runner.invoke(app, ["visualize", "attention", ck, "--task", "sgn", "--out", str(tmp_path), "--rows", "2"])
    assert r.exit_code == 0, r.output
    r = runner.invoke(app, ["visualize", "attention", ck, "--task", "eqa", "--out", str(tmp_path), "--rows", "2"])
    assert r.exit_code == 0 and len(list(tmp_path.glob("attention-eqa-*.png"))) == 1, r.output
    r = runner.invoke(app, ["video", ck, "--episodes", "1", "--out", str(tmp_path)])
    assert r.exit_code == 0, r.output
    gifs = sorted(tmp_path.glob("*.gif"))
    assert [g.name.split("-")[-2] for g in gifs] == ["eqa", "sgn"]
    # each GIF holds a whole episode: its steps at 150 ms, then the outcome for 5 × 150 (durations, not a frame count:
    # the encoder merges identical frames), under the sentence the command printed for it
    for gif in gifs:
        frames = _gif(gif)
        total = sum(d for _, d in frames)
        assert total % 150 == 0 and total >= 150 * 6, total
        sentence = r.output.split(f"wrote {gif} ('", 1)[1].split("': ", 1)[0]
        picture = frames[-1][0][22:].astype(np.uint8)
        outcome = r.output.split(f"wrote {gif} ('{sentence}': ", 1)[1].split(")", 1)[0]
        assert outcome in ("success", "failure")
        if gif.name.split("-")[-2] == "sgn":  # an EQA caption also names the answer word: read on SGN
            assert _caption_gap(frames[-1][0], picture, f"{sentence}: {outcome}") < 2
    assert len(list(tmp_path.glob("channels-*.png"))) == 1 and len(list(tmp_path.glob("attention-sgn-*.png"))) == 1
    bad = runner.invoke(app, ["visualize", "attention", ck, "--task", "nav"], env={"COLUMNS": "200"})
    assert bad.exit_code == 2 and "'nav' is not one of 'sgn', 'eqa'" in bad.output


def _gif(path) -> list[tuple[np.ndarray, int]]:
    """A GIF's frames as RGB arrays, each with its duration (ms)."""
    with Image.open(path) as gif:
        return [(np.asarray(f.convert("RGB"), dtype=float), f.info["duration"]) for f in ImageSequence.Iterator(gif)]


def _caption_gap(frame: np.ndarray, picture: np.ndarray, text: str) -> float:
    """How far a GIF frame's caption strip is from ``text`` captioned over ``picture`` (mean absolute difference)."""
    from emml.report.oracle_video import CAPTION_HEIGHT, _captioned

    expected = np.asarray(_captioned(picture, text), dtype=float)[:CAPTION_HEIGHT]
    return float(np.abs(frame[:CAPTION_HEIGHT] - expected).mean())


def test_a_gif_per_episode(checkpoints, tmp_path, no_leftovers):
    """The GIF's content (issue 66: it was checked for two frames): every step shown 150 ms and the outcome 5 × 150
    (identical consecutive frames are merged by the encoder, their durations added), the first frame the episode's
    first picture under its caption, the last its last picture under its own."""
    from emml.envs.doom import MOVES
    from emml.report.oracle_video import CAPTION_HEIGHT

    model, cfg = load_model(checkpoints[True])
    ep = record_episode(model, cfg.env, "sgn", seed=0)
    frames = _gif(episode_gif(ep, tmp_path / "e.gif"))
    assert sum(d for _, d in frames) == 150 * (len(ep.frames) + 5)
    (first, _), (last, _) = frames[0], frames[-1]
    assert first.shape == (ep.frames[0].shape[0] + CAPTION_HEIGHT, *ep.frames[0].shape[1:])
    assert np.abs(first[CAPTION_HEIGHT:] - ep.frames[0]).mean() < 8  # the picture, up to the GIF's palette
    assert np.abs(last[CAPTION_HEIGHT:] - ep.frames[-1]).mean() < 8
    # the captions as drawn (at the smoke width the move and the outcome run past the frame's right edge)
    assert _caption_gap(first, ep.frames[0], f"{ep.sentence} | t=0 {MOVES[ep.moves[0]]}") < 2
    assert _caption_gap(last, ep.frames[-1], f"{ep.sentence}: {'success' if ep.success else 'failure'}") < 2
    assert _caption_gap(first, ep.frames[0], "") > 2  # a caption is there: not a blank strip


def test_reports_index_links_tables_curves_and_the_best_runs_figures(checkpoints, tmp_path, monkeypatch, no_leftovers):
    import shutil

    from emml.report.index import write_reports
    from emml.runs.rundir import record_result

    # the two smoke runs recorded as table2 rows of the demo profile (the index never lists smoke), their run dirs
    # where table2 keeps them
    monkeypatch.setenv("MLFLOW_TRACKING_URI", f"sqlite:///{tmp_path}/mlflow.db")
    for aux, ckpt in checkpoints.items():
        model, cfg = load_model(ckpt)
        cfg.table, cfg.run_root, cfg.results_root = "table2", str(tmp_path / "runs"), str(tmp_path / "results")
        cfg.profile = "demo"
        if not aux:  # Table 2's No Aux Dual-Attention keeps the answer loss to the GA2 gate for 400k frames (issue 48)
            cfg.model_options = {**cfg.model_options, "answer_gate_frames": 400000}
        name = f"dual_attention-easy-{'aux' if aux else 'noaux-warm400000'}-s0-demo"
        shutil.copytree(ckpt.parent, tmp_path / "runs" / "table2" / name)
        payload = {
            "run_name": name,
            "table": "table2",
            "model": "dual_attention",
            "difficulty": "easy",
            "aux": aux,
            "seed": 0,
            "profile": "demo",
            "frames": 64,
            "git_sha": "12e0077",
            "run_id": "x",
            "eval_episodes": 1,
            "metrics": {"sgn_train": 0.5, "sgn_test": 0.5, "eqa_train": 0.5, "eqa_test": 0.5},
        }
        record_result(payload, cfg)
    index = write_reports(tmp_path / "reports", tmp_path / "results", tmp_path / "runs", log=lambda m: None)
    text = index.read_text()
    assert "## Profile `demo`" in text and "**table2** (2 runs, frames 64)" in text
    assert "[table2-demo.md](table2-demo.md)" in text
    assert "figures of the best Dual-Attention run `dual_attention-easy-aux-s0-demo`" in text
    run = "table2-dual_attention-easy-aux-s0-demo"  # named by table and run (issue 60)
    for link in (f"channels-{run}.png", f"attention-sgn-{run}-s0.png", f"attention-eqa-{run}-s1.png"):
        assert f"({link})" in text and (tmp_path / "reports" / link).exists()


def test_the_channel_figure_compares_with_the_finished_no_aux_run_the_table_declares(checkpoints, tmp_path):
    """Table 2's No Aux Dual-Attention run is `…-noaux-warm400000-…` (its `noaux_overrides`, issue 48), not the same
    run with aux=False (the collapsed `…-noaux-…` run, which stays in runs/ as evidence); an interrupted one (a
    checkpoint, no results) or one not there is no column."""
    import shutil

    from emml.report.index import finished_no_aux
    from emml.report.plan import plan_report
    from emml.runs.rundir import RESULTS

    runs = tmp_path / "runs"
    names = {True: "dual_attention-easy-aux-s0-demo", False: "dual_attention-easy-noaux-warm400000-s0-demo"}
    for aux, ckpt in checkpoints.items():
        shutil.copytree(ckpt.parent, runs / "table2" / names[aux])
    shutil.copytree(checkpoints[False].parent, runs / "table2" / "dual_attention-easy-noaux-s0-demo")  # collapsed
    plan = plan_report("table2", "demo", tmp_path / "results", runs)
    best, no_aux = plan.by_name()[names[True]], runs / "table2" / names[False]
    assert finished_no_aux(plan, best) == no_aux / CHECKPOINT
    (no_aux / RESULTS).unlink()  # interrupted: a checkpoint, no results
    assert finished_no_aux(plan, best) is None
    shutil.rmtree(no_aux)  # not there: no column, not the collapsed run's
    assert finished_no_aux(plan, best) is None
