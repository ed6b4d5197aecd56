"""The paper's claims as data (reproduce/claims.toml, emml/experiments/claims/claim.py): the committed file loads and
names real rows, metrics and columns; a bad claim fails naming the file, the claim and the allowed values."""

import pytest

from emml.experiments.claims import KINDS, load_claims
from emml.experiments.tables import load_table


def test_the_committed_claims_load_and_point_at_their_tables():
    claims = load_claims()
    assert {"da-best-easy-aux", "da-best-hard-aux", "da-best-easy-noaux", "house-da-best", "transfer-hard"} <= set(
        claims
    )
    for claim in claims.values():
        assert claim.kind in KINDS
        labels = {r.label for r in load_table(claim.table).rows}
        assert set(claim.rows) <= labels and (claim.than is None or claim.than in labels)
    assert claims["da-best-hard-aux"].where == {"difficulty": "hard", "aux": True}
    assert claims["aux-helps"].rows == tuple(r.label for r in load_table("table2").rows)  # no rows: all of them
    assert claims["shaping-speed"].mark == "chance" and claims["shaping-speed"].metrics == ("sgn_train",)
    assert claims["noaux-channels-align"].metrics == ("sgn_test",)  # the table's first: the cell whose runs it reads
    assert claims["noaux-channels-align"].relative == {"aux": True}  # half the Aux run's own AP
    assert claims["multitask-helps"].inferred and not claims["da-best-easy-aux"].inferred


GOOD = 'id = "x"\ntext = "t"\nsource = "s"\ntable = "table2"\nmetrics = ["sgn_test"]\n'


@pytest.mark.parametrize(
    "body, message",
    [
        ('kind = "wins"\nrow = "GA"\n', r"key 'claims\[0\].kind': 'wins' is not allowed; choose one of best, below"),
        ('kind = "best"\n', r"kind='best' needs 'row'"),
        ('kind = "best"\nrow = "GPT"\n', r"row 'GPT' is not a row of table2; allowed: Text only"),
        ('kind = "best"\nrow = "GA"\nwhere = { difficulty = "house" }\n', r"where.difficulty='house' is not a column"),
        (
            'kind = "best"\nrow = "GA"\nwhere = { seed = 0 }\n',
            r"key 'claims\[0\].where.seed': unknown key; allowed keys: difficulty, aux$",
        ),
        ('kind = "level"\nrows = ["GA"]\nthan = "FiLM"\n', r"kind='level' needs 'margin'"),
        (
            'kind = "best"\nrow = "GA"\nweight = 2\n',
            r"key 'claims\[0\].weight': unknown key; allowed keys: id, text, source, kind, table, row",
        ),
        (
            'kind = "faster"\nrows = ["GA"]\nthan = "FiLM"\nmark = "0.7"\n',
            r"key 'claims\[0\].mark': '0.7' is not allowed; choose one of chance, 0.5, 0.9$",
        ),
        ('kind = "best"\nrow = "GA"\nmark = "0.5"\n', r"mark='0.5' is not allowed; allowed: kind='faster' only"),
        ('kind = "diagnostic"\nrows = ["GA"]\nvalue = 0.5\n', r"kind='diagnostic' needs 'key'"),
        ('kind = "harder"\n', r"metrics=\['sgn_test'\]: kind='harder' compares 2, the harder task's first"),
        ('kind = "best"\nrow = "GA"\nrelative = { aux = true }\n', r"relative: kind='diagnostic' only"),
        (
            'kind = "diagnostic"\nrows = ["GA"]\nvalue = 0.5\nkey = "diag/x"\nrelative = { aux = "yes" }\n',
            r"key 'claims\[0\].relative.aux': must be true or false, got 'yes'",
        ),
        ('kind = "diagnostic"\nrows = ["GA"]\nvalue = 0.5\nkey = "eval/x"\n', r"key='eval/x': kind='diagnostic' only"),
    ],
)
def test_a_bad_claim_fails_naming_the_file_and_the_field(tmp_path, body, message):
    path = tmp_path / "claims.toml"
    path.write_text("[[claims]]\n" + GOOD + body)
    with pytest.raises(ValueError, match=message) as e:
        load_claims(path)
    assert "claims.toml" in str(e.value)


def test_a_claim_id_is_unique(tmp_path):
    path = tmp_path / "claims.toml"
    one = "[[claims]]\n" + GOOD + 'kind = "best"\nrow = "GA"\n'
    path.write_text(one + one)
    with pytest.raises(ValueError, match="id='x' is used twice"):
        load_claims(path)


def test_a_claim_reads_a_test_column_or_its_train_twin_and_nothing_else(tmp_path):
    path = tmp_path / "claims.toml"
    head = GOOD.replace('metrics = ["sgn_test"]\n', "") + 'kind = "best"\nrow = "GA"\n'
    path.write_text("[[claims]]\n" + head + 'metrics = ["eqa_train"]\n')
    assert load_claims(path)["x"].metrics == ("eqa_train",)
    path.write_text("[[claims]]\n" + head + 'metrics = ["eqa_val"]\n')
    with pytest.raises(ValueError, match=r"'eqa_val' is not a column of table2; allowed: sgn_test, eqa_test, sgn_"):
        load_claims(path)


@pytest.mark.parametrize(
    "text, message",
    [
        (
            '[[claims]]\nid = "x"\ntext = "t"\nsource = "s"\ntable = "table9"\nkind = "best"\nrow = "GA"\n',
            r": claims\[0\]\.table: 'table9' is unknown; choose one of 'table2', ",
        ),
        (
            'claims = "all of them"\n',
            r": key 'claims': must be a non-empty array of tables \(\[\[claims\]\]\), got 'all of them'",
        ),
        ("claims = [1]\n", r": key 'claims\[0\]': must be a table, got 1"),
        ("# no claims\n", r": key 'claims': missing"),
    ],
)
def test_a_claim_of_an_unknown_table_or_shape_is_named_by_file_and_key_path(tmp_path, text, message):
    """Issue 65: an unknown table said "table='table9' is unknown", naming neither the file nor claims[0].table (and
    stopped `emml campaign status reference`)."""
    path = tmp_path / "claims.toml"
    path.write_text(text)
    with pytest.raises(ValueError, match=rf"^{path}{message}") as e:
        load_claims(path)
    assert "\n" not in str(e.value)
