"""The offline probe of the EQA question encoder (emml/eval/probe_eqa.py, issue 34): its result's structure, what it
trains (the GRU and Linear of a fresh x_sent encoder) and what it keeps frozen (the checkpoint's embedding and the
rest of the model), and its refusals before any engine starts."""

import dataclasses
import json
import time

import pytest
import torch
from typer.testing import CliRunner

import emml.eval.probe_eqa as probe
from emml.cli import app
from emml.config.profiles import profile_config
from emml.models import build_model
from emml.runs.checkpoint import save_checkpoint
from emml.tasks.language import load_dataset, resolve_vocabulary
from tests.conftest import engine_pids, shm_files

runner = CliRunner()
SMALL = {"episodes": 2, "seeds": 1, "steps": 5, "batch": 8}
"""Two first frames per question, one encoder of five steps per readout."""


def _config(**env):
    cfg = profile_config("smoke", "easy", {"env.tasks": "eqa", **{f"env.{k}": v for k, v in env.items()}}, aux=True)
    return cfg, resolve_vocabulary(cfg.env.vocabulary, load_dataset(cfg.env.dataset)).words


def _model(cfg, words, name="dual_attention", **options):
    torch.manual_seed(0)
    e = cfg.env
    return build_model(name, len(words), e.height, e.width, e.max_steps, **{**cfg.model_options, **options})


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory):
    """A smoke-sized Dual-Attention EQA checkpoint (the trainer's payload; its weights freshly initialised: the
    probe reads a checkpoint's weights, whatever they learned)."""
    cfg, words = _config()
    path = tmp_path_factory.mktemp("probe") / "checkpoint.pt"
    model = _model(cfg, words)
    save_checkpoint(path, {"model": model.state_dict(), "config": cfg.to_dict(), "frames": 0, "vocabulary": words})
    return path


@pytest.fixture(scope="module")
def frames(checkpoint):
    """The probe's frames on the checkpoint (two per question), collected once for the tests that train on them;
    every engine it starts ended (`no_leftovers`' check: that fixture is per test)."""
    model, cfg = probe.load_model(checkpoint)
    pids, shm = engine_pids(), set(shm_files())
    data = probe.collect_frames(model, cfg, probe.probe_questions(model, cfg), episodes=2)
    deadline = time.monotonic() + 5  # an engine ends within moments of its close
    while time.monotonic() < deadline and (engine_pids() - pids or set(shm_files()) - shm):
        time.sleep(0.05)
    assert engine_pids() - pids == set() and set(shm_files()) - shm == set()
    return model, cfg, data


def test_the_result_has_its_documented_structure(checkpoint, no_leftovers):
    result = probe.probe_checkpoint(checkpoint, probe.ProbeOptions(readouts=("last", "mean"), **SMALL))
    questions = {s: [x.text for x in load_dataset("doom").select("eqa", s)] for s in ("train", "test")}
    assert result["checkpoint"] == str(checkpoint) and result["questions"] == questions
    assert result["frames"] == {"train": 2 * 21, "test": 2 * 8} and result["seed"] == probe.SEED
    assert (result["readout"], result["x_image"], result["steps"]) == ("last", "sigmoid", 5)
    scores = [result["checkpoint_encoder"]]
    assert list(result["readouts"]) == ["last", "mean"]
    for r in result["readouts"].values():
        assert [x["seed"] for x in r["runs"]] == [0]
        scores += [*r["runs"], r["mean"]]
        assert r["mean"]["test"] == r["runs"][0]["test"]  # one seed: its own mean
    for score in scores:
        for split in ("train", "test"):
            assert 0.0 <= score[split] <= 1.0
            per_question = score["per_question"][split]
            assert list(per_question) == questions[split] and all(0.0 <= a <= 1.0 for a in per_question.values())
            # two frames per question: the split's accuracy is the mean of its questions'
            assert score[split] == pytest.approx(sum(per_question.values()) / len(per_question))
    json.dumps(result)  # --json prints it whole
    text = probe.probe_table(result)
    assert "checkpoint ('last')" in text and "retrained 'mean'" in text and "what color is the torch" in text
    assert result["activation"] == "relu" and "x_sent = relu(Linear)" in text
    assert all(isinstance(c, int) for r in scores[:1] for c in r["closed"])


def test_each_frame_is_its_episodes_first_with_its_own_seed(frames, no_leftovers):
    model, cfg, data = frames
    train, test = data["train"], data["test"]
    assert train["x_image"].shape[:2] == (2 * 21, model.vocab_size) and len(test["answer"]) == 2 * 8
    assert train["x_image"].min() >= 0 and train["x_image"].max() <= 1  # sigmoid(conv3)
    assert train["question"].tolist() == [j for j in range(21) for _ in range(2)]
    vocab = resolve_vocabulary(None, load_dataset("doom")).words
    groups = load_dataset("doom").word_groups
    answers = torch.cat([train["answer"], test["answer"]]).tolist()
    assert {vocab[a] for a in answers} <= set(groups["colors"]) | set(groups["objects"])
    # the second episode of the first test question: seed SEED + 21 * 2 (the training questions' episodes) + 1
    env = probe.make_env(dataclasses.replace(cfg.env, tasks="eqa", split="test", aux_labels=False))
    try:
        obs, _ = env.reset(seed=probe.SEED + 21 * 2 + 1, options={"sentence": test["questions"][0]})
        answer = env.answer_id
    finally:
        env.close()
    x_image = probe.image_features(model, torch.as_tensor(obs["image"])[None])[0]
    assert torch.allclose(x_image, test["x_image"][1], atol=1e-5) and answer == test["answer"][1]  # conv batching
    assert not torch.equal(test["x_image"][0], test["x_image"][1])  # another seed, another scene


def test_only_the_gru_and_linear_learn_the_embedding_stays_the_checkpoints(frames):
    model, _, data = frames
    before = {k: v.clone() for k, v in model.state_dict().items()}
    rng = torch.get_rng_state()
    fresh = probe.fresh_encoder(model, "last", seed=0, init="fresh")
    trained = probe.train_encoder(model, data["train"], "last", seed=0, steps=5, batch=8, init="fresh")
    assert torch.equal(torch.get_rng_state(), rng)  # the global RNG untouched
    assert torch.equal(trained.embedding.weight, model.text_encoder.embedding.weight)
    assert not trained.embedding.weight.requires_grad
    assert not torch.equal(trained.gru.weight_ih_l0, fresh.gru.weight_ih_l0)
    assert not torch.equal(trained.linear.weight, fresh.linear.weight)
    assert all(torch.equal(v, before[k]) for k, v in model.state_dict().items())  # the checkpoint's model frozen
    again = probe.train_encoder(model, data["train"], "last", seed=0, steps=5, batch=8, init="fresh")
    assert torch.equal(again.linear.weight, trained.linear.weight)  # the seed draws weights and minibatches
    start = probe.fresh_encoder(model, "mean", seed=0)  # init 'checkpoint': the readout is all that differs
    assert all(torch.equal(v, model.text_encoder.state_dict()[k]) for k, v in start.state_dict().items())
    assert start.readout == "mean" and not start.embedding.weight.requires_grad
    with pytest.raises(ValueError, match="init='warm' is not allowed"):
        probe.ProbeOptions(2, ("last",), 1, 5, init="warm").validate()


def test_the_readouts_give_different_encoders(frames):
    model, _, data = frames
    last = probe.train_encoder(model, data["train"], "last", seed=0, steps=5, batch=8)
    mean = probe.train_encoder(model, data["train"], "mean", seed=0, steps=5, batch=8)
    assert (last.readout, mean.readout) == ("last", "mean")
    with torch.no_grad():
        tokens = data["test"]["tokens"]
        assert not torch.allclose(last(tokens)[1], mean(tokens)[1])


def test_the_activation_reaches_the_retrained_encoder_and_closed_channels_are_counted(frames):
    """`ProbeOptions.activation` (issue 34): softplus in place of ReLU on the retrained Linear; `closed` lists the
    answer channels whose gate stays below CLOSED_BELOW for every question (under ReLU: dead)."""
    model, _, data = frames
    soft = probe.train_encoder(model, data["train"], "last", seed=0, steps=5, batch=8, activation="softplus")
    assert soft.activation is torch.nn.functional.softplus
    answers = sorted(int(a) for a in torch.cat([data[s]["answer"] for s in ("train", "test")]).unique())
    shut = probe._scores(model, data, lambda tokens: torch.zeros(len(tokens), model.vocab_size))
    assert shut["closed"] == answers  # a gate closed everywhere closes every answer channel
    opened = torch.zeros(model.vocab_size)
    opened[answers[0]] = 1.0
    some = probe._scores(model, data, lambda tokens: opened.expand(len(tokens), -1))
    assert some["closed"] == answers[1:]
    with pytest.raises(ValueError, match="activation='tanh' is not allowed"):
        probe.ProbeOptions(activation="tanh").validate()


@pytest.mark.parametrize(
    "name, options, why",
    [
        ("ga", {}, "no GA2 gate in model 'ga'"),
        ("da_no_ga2", {}, "the 'w/o GA2' ablation"),
        ("dual_attention", {"control": "detectors"}, "control 'detectors'"),
    ],
)
def test_a_model_without_a_gate_to_probe_is_refused_before_any_engine(monkeypatch, name, options, why):
    cfg, words = _config()
    model = _model(cfg, words, name, **options)
    monkeypatch.setattr(probe, "load_model", lambda path: (model, cfg))
    monkeypatch.setattr(probe, "make_env", _no_engine)
    with pytest.raises(ValueError, match=why):
        probe.probe_checkpoint("any.pt", probe.ProbeOptions(**SMALL))


def test_a_run_not_scored_on_eqa_is_refused_before_any_engine(monkeypatch):
    cfg, words = _config(tasks="sgn")
    monkeypatch.setattr(probe, "load_model", lambda path: (_model(cfg, words), cfg))
    monkeypatch.setattr(probe, "make_env", _no_engine)
    with pytest.raises(ValueError, match="not scored on EQA"):
        probe.probe_checkpoint("any.pt", probe.ProbeOptions(**SMALL))


def _no_engine(cfg):
    raise AssertionError("the probe started an engine")


@pytest.mark.parametrize(
    "args, named",
    [
        (["--readouts", "last,max"], "readouts='max'"),
        (["--readouts", ","], "readouts=()"),
        (["--episodes", "0"], "episodes=0"),
        (["--seeds", "0"], "seeds=0"),
        (["--lr", "0"], "lr=0.0"),
        (["--activation", "tanh"], "'tanh' is not one of 'relu', 'softplus'"),
    ],
)
def test_the_cli_names_a_bad_option_before_loading(args, named, tmp_path):
    # no checkpoint read: no such file
    result = runner.invoke(app, ["probe-eqa", str(tmp_path / "nope.pt"), *args], env={"COLUMNS": "200"})
    assert result.exit_code == 2 and named in result.output and "no such file" not in result.output, result.output
    if "readouts='max'" in named:
        assert "'last', 'mean'" in result.output


def test_the_cli_prints_the_table_or_the_json(checkpoint, no_leftovers):
    args = ["probe-eqa", str(checkpoint), "--episodes", "1", "--seeds", "1", "--steps", "2", "--batch", "4"]
    text = runner.invoke(app, [*args, "--readouts", "mean"])
    assert text.exit_code == 0, text.output
    assert "retrained 'mean'" in text.output and "retrained 'last'" not in text.output
    data = json.loads(runner.invoke(app, [*args, "--json"]).stdout)
    assert list(data["readouts"]) == ["last", "mean"] and data["frames"] == {"train": 21, "test": 8}
    assert set(data["checkpoint_encoder"]["per_question"]["test"]) == set(data["questions"]["test"])


def test_eq1_over_the_content_words_masks_the_function_words_only(frames):
    """``eq1_words='content'``: Eq. 1 reads x_BoW without the function words; the answers change only through it."""
    model, cfg, data = frames
    mask = probe.eq1_mask(cfg, "content")
    words = resolve_vocabulary(cfg.env.vocabulary, load_dataset(cfg.env.dataset)).words
    assert {w for w, m in zip(words, mask) if m == 0} == {
        "go",
        "to",
        "the",
        "object",
        "what",
        "color",
        "is",
        "which",
        "in",
    }
    assert probe.eq1_mask(cfg, "all") is None
    train = data["train"]
    gate = model.sentence_gate(train["tokens"])
    masked = {**train, "eq1_mask": mask}
    x_bow = model.text_encoder.bag_of_words(train["tokens"])
    expected = model.fusion(train["x_image"], x_bow * mask, gate).answer_logits
    torch.testing.assert_close(probe.answer_logits(model, masked, gate), expected)
    assert not torch.allclose(probe.answer_logits(model, train, gate), expected)
    with pytest.raises(ValueError, match="eq1_words='some' is not allowed"):
        probe.ProbeOptions(2, ("last",), 1, 5, eq1_words="some").validate()
