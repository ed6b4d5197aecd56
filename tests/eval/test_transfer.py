"""Transfer to new words (§5.4, Table 4): the surgery changes nothing for instructions without the new words, wires
each new word to its own detector channel, and refuses what it cannot transfer; the table's rows cover every
test instruction; a smoke run is scored end to end."""

import json
import re
from pathlib import Path

import pytest
import torch

from emml.eval.transfer import LabelDetector, append_words, check_transferable, make_detector
from emml.models import build_model
from emml.tasks.language import Vocabulary, load_dataset

WORDS = ("red", "pillar")
T, B, H, W = 2, 3, 60, 108
GRID = (2, 5)
"""conv3 grid of a 60×108 image."""


@pytest.fixture(scope="module")
def vocab():
    return Vocabulary.from_dataset(load_dataset("doom"), "train_instructions")


def _model(vocab, name="dual_attention", seed=0):
    torch.manual_seed(seed)
    return build_model(name, len(vocab), H, W, 210).eval()


def _obs(vocab, text, aux=None, seed=0):
    g = torch.Generator().manual_seed(seed)
    obs = {
        "image": torch.randint(0, 256, (T, B, 3, H, W), dtype=torch.uint8, generator=g),
        "tokens": torch.tensor([vocab.encode(text, 10)] * (T * B)).view(T, B, 10),
        "task": torch.zeros(T, B, dtype=torch.long),
        "time": torch.arange(T)[:, None].expand(T, B).contiguous(),
    }
    obs["aux"] = (
        aux if aux is not None else torch.randint(0, 2, (T, B, len(vocab), *GRID), dtype=torch.uint8, generator=g)
    )
    return obs


def _transferred(vocab, seed=0):
    model = _model(vocab, seed=seed)
    extended = vocab.extend(WORDS)
    new, new_vocab = append_words(model, vocab, WORDS, make_detector("labels", extended, WORDS), seed=seed)
    return model, new, new_vocab


def _run(model, obs):
    start = torch.zeros(T, B, dtype=torch.bool)
    start[0] = True
    with torch.no_grad():
        return model(obs, model.initial_state(B), start)[0]


@pytest.mark.parametrize("text", ["go to the tall green torch", "go to the smallest object", "go to the armor"])
def test_surgery_leaves_every_output_unchanged_without_the_new_words(vocab, text):
    model, new, new_vocab = _transferred(vocab)
    obs = _obs(new_vocab, text)  # the same tokens in both vocabularies: old ids are kept
    before = _run(model, {k: v for k, v in obs.items() if k != "aux"})
    after = _run(new, obs)
    for field in ("logits", "value", "answer_logits", "aux_logits", "attention"):
        assert torch.equal(getattr(before, field), getattr(after, field)), field


def test_surgery_grows_only_the_vocabulary_side(vocab):
    model, new, new_vocab = _transferred(vocab)
    assert new_vocab.words == vocab.words + WORDS and model.detector is None  # the original is untouched
    old, emb = model.text_encoder.embedding.weight, new.text_encoder.embedding.weight
    assert emb.shape == (len(vocab) + 3, old.shape[1]) and torch.equal(emb[: len(vocab) + 1], old)
    assert not torch.equal(emb[-1], emb[-2])  # fresh rows, one per word
    again = _transferred(vocab)[1].text_encoder.embedding.weight
    assert torch.equal(again, emb)  # seeded: the same surgery gives the same rows
    changed = {n for n, p in new.state_dict().items() if p.shape != model.state_dict()[n].shape}
    assert changed == {"text_encoder.embedding.weight"}
    same = [n for n, p in new.state_dict().items() if n not in changed]
    assert all(torch.equal(new.state_dict()[n], model.state_dict()[n]) for n in same)


@pytest.mark.parametrize("word", WORDS)
def test_each_new_channel_is_gated_by_its_own_word(vocab, word):
    """Lighting one cell in a word's detector channel moves the attention there only when the instruction holds
    that word (Eq. 1-2); the other new word's channel is not read."""
    _, new, ext = _transferred(vocab)
    other = next(w for w in WORDS if w != word)
    h, w = new.grid
    for text, reads in ((f"go to the {word} object" if word == "red" else "go to the pillar", True),):
        for channel, expect in ((word, reads), (other, False)):
            aux = torch.zeros(T, B, len(ext), h, w, dtype=torch.uint8)
            base = _run(new, _obs(ext, text, aux=aux)).attention
            aux[:, :, ext.index(channel), 1, 3] = 1
            lit = _run(new, _obs(ext, text, aux=aux)).attention
            moved = bool((lit[..., 1, 3] > base[..., 1, 3]).all())
            assert moved == expect, (text, channel)


def test_label_detector_reads_the_new_words_channels():
    aux = torch.zeros(1, 2, 5, 3, 4, dtype=torch.uint8)
    aux[0, 1, 3, 2, 1] = 1
    out = LabelDetector([3, 4])({"aux": aux})
    assert out.shape == (2, 2, 3, 4) and out.dtype == torch.float32 and out[1, 0, 2, 1] == 1 and out.sum() == 1


def test_refuses_what_it_cannot_transfer(vocab):
    with pytest.raises(ValueError, match="already in the model's vocabulary"):
        check_transferable(_model(vocab), vocab.extend(["red"]), WORDS)
    for name in ("ga", "da_no_ga1", "da_no_sa"):
        with pytest.raises(ValueError, match="Dual-Attention model with GA1"):
            check_transferable(_model(vocab, name), vocab, WORDS)
    with pytest.raises(ValueError, match="distinct"):
        check_transferable(_model(vocab), vocab, ("red", "red"))
    with pytest.raises(ValueError, match="detector='yolo' is unknown; allowed: labels"):
        make_detector("yolo", vocab.extend(WORDS), WORDS)


def test_table4_rows_cover_every_test_instruction_once():
    from emml.experiments.tables import load_table

    table = load_table("table4")
    test = {s.text for s in load_dataset("doom").select("sgn", "test")}
    texts = [x for r in table.rows for x in r.instructions]
    assert sorted(texts) == sorted(test) and len(texts) == 28
    paper_rows = [r for r in table.rows if not r.extra]
    assert len(paper_rows) == 8 and sum(len(r.instructions) for r in paper_rows) == 14
    runs = table.runs([0, 1])
    assert len(runs) == 4 and {r.difficulty for r in runs} == {"easy", "hard"}
    cfg = runs[0].to_config("smoke")
    assert cfg.env.tasks == "sgn" and cfg.env.vocabulary == "train_instructions" and cfg.aux
    assert table.cell_columns("Go to the tall/short pillar", "sgn_transfer") == [
        "sgn_transfer:go to the tall pillar",
        "sgn_transfer:go to the short pillar",
    ]


@pytest.mark.parametrize(
    "old, new, key, message",
    [
        ('detector = "labels"', 'detector = "yolo"', "transfer.detector", "choose one of labels"),
        ('"env.vocabulary" = "train_instructions"', '"env.vocabulary" = "x"', "transfer.overrides", "vocabulary"),
        ('["go to the pillar"]', '["go to the torch"]', "rows[0].instructions", "not an SGN test instruction"),
        ('["go to the red object"]', '["go to the pillar"]', "rows[1].instructions", "already in row"),
        (
            'label = "Go to the red pillar"\ninstructions = ["go to the red pillar"]\n',
            "",
            "rows",
            "missing.*red pillar",
        ),
    ],
)
def test_a_broken_table4_names_the_key(tmp_path, old, new, key, message):
    from emml.config.paths import REPRODUCE_DIR
    from emml.experiments.tables import load_table

    text = (REPRODUCE_DIR / "table4.toml").read_text()
    assert old in text
    path = tmp_path / "table4.toml"
    path.write_text(text.replace(old, new, 1).replace("[[rows]]\n\n", ""))
    with pytest.raises(ValueError, match=f"key {re.escape(repr(key))}.*{message}"):
        load_table("table4", path)


def _small_train(cfg, **kwargs):
    """The trainer on a smaller smoke run: 64 frames, one episode per evaluated instruction (12-step episodes:
    `_short_episodes`)."""
    from emml.config.schema import apply_overrides
    from emml.rl.trainer import train

    small = apply_overrides(cfg, {"frames": 64, "diagnose_episodes": 0, "eval_episodes": 1})
    return train(small, **kwargs)


def _short_episodes(monkeypatch, tmp_path) -> None:
    """The smoke profile with 12-step episodes: an episode's length is part of a run's identity (its name), so
    the training runs and the report that looks them up must both see it."""
    import emml.config.profiles

    text = emml.config.profiles.PROFILES_FILE.read_text()
    path = tmp_path / "profiles.toml"
    path.write_text(text.replace("[smoke]\n", '[smoke]\n"env.max_steps" = 12\n', 1))
    monkeypatch.setenv(emml.config.profiles.PROFILES_ENV, str(path))  # the launcher's run processes too


def test_make_transfer_smoke_fills_every_row(tracking, monkeypatch, tmp_path, no_leftovers):
    """`emml run table4 --profile smoke` end to end: two training runs, each scored on the 28 test instructions
    after the surgery; the report fills all 15 rows for Easy and Hard; a second launch redoes nothing."""
    _short_episodes(monkeypatch, tmp_path)
    from emml.eval import transfer
    from emml.experiments.launch import run_table
    from emml.report.cells import EXTRA_MARK
    from emml.report.tables import report_table
    from emml.runs.results import read_results

    roots = {"run_root": tracking["run_root"], "results_root": tracking["results_root"]}
    report = run_table("table4", "smoke", jobs=1, train_fn=_small_train, log=lambda m: None, **roots)
    assert not report.failed and len(report.done) == 2
    results = read_results(f"{roots['results_root']}/table4/smoke.csv")
    columns = [c for c in results.columns if c.startswith("sgn_transfer:")]
    assert len(columns) == 28 and results[columns].notna().all().all() and len(results) == 2
    assert set(results["transfer_words"]) == {"red,pillar"} and "sgn_test" not in results.columns  # not encodable
    rep = report_table("table4", "smoke", out=tracking["run_root"], **roots)
    assert len(rep["cells"]) == 30 and all(c["n"] == 1 for c in rep["cells"])
    md = (Path(tracking["run_root"]) / "table4-smoke.md").read_text()
    assert f"Go to the red tall/short pillar {EXTRA_MARK}" in md and "no fine-tuning" in rep["caption"]

    def fail(*args, **kwargs):
        raise AssertionError("a recorded transfer run was scored again")

    # `emml transfer` on one of the runs: the table's rows and every instruction; words it knows are refused
    from typer.testing import CliRunner

    from emml.cli import app

    ckpt = next(Path(roots["run_root"]).glob("table4/*easy*/checkpoint.pt"))
    result = CliRunner().invoke(app, ["transfer", str(ckpt), "--episodes", "1", "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert len(data["instructions"]) == 28 and len(data["rows"]) == 15
    result = CliRunner().invoke(app, ["transfer", str(ckpt), "--words", "red,torch"])
    assert result.exit_code == 2 and "['torch'] are already in the model's vocabulary" in result.output

    monkeypatch.setattr(transfer, "transfer_checkpoint", fail)
    again = run_table("table4", "smoke", jobs=1, train_fn=_small_train, log=lambda m: None, **roots)
    assert again.skipped and not again.done and not again.failed


def test_eval_settings_leave_out_splits_with_unknown_words():
    from emml.config.schema import DoomConfig
    from emml.eval.evaluate import eval_settings

    assert eval_settings(DoomConfig(tasks="sgn", vocabulary="train_instructions")) == [("sgn", "train", None)]
    assert len(eval_settings(DoomConfig())) == 4
    with pytest.raises(
        ValueError, match="vocabulary='train_words' must be a list of words or one of 'all', 'train_instructions'"
    ):
        DoomConfig(vocabulary="train_words").validate()


def test_reset_plays_the_chosen_sentence_and_names_a_bad_one(no_leftovers):
    from emml.config.schema import DoomConfig
    from emml.envs.doom import DoomEnv

    env = DoomEnv(DoomConfig(tasks="sgn", split="test", height=60, width=108))
    try:
        with pytest.raises(ValueError, match="sentence='go to the torch' is not one of this env's sentences"):
            env.reset(options={"sentence": "go to the torch"})
        with pytest.raises(ValueError, match=r"reset options \['colour'\] are unknown; allowed: 'sentence'"):
            env.reset(options={"colour": "red"})
        for seed in range(3):
            env.reset(seed=seed, options={"sentence": "go to the red pillar"})
            assert env.episode.sentence.text == "go to the red pillar"
    finally:
        env.close()
