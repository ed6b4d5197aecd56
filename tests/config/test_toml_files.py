"""The one checker of the project's TOML files (emml/config/toml_files.py): a format declared as pydantic sections,
every failure one message naming the file, the key path and what is wrong, with the allowed keys or values."""

from __future__ import annotations

from typing import Annotated, Any, Literal

import pytest
from pydantic import AfterValidator, Field

from emml.config.toml_files import FileError, Section, check_file, read_toml


def _even(n: int) -> int:
    if n % 2:
        raise ValueError(f"{n} is odd; an even number is needed")
    return n


class Item(Section):
    name: Annotated[str, "a string"]
    colour: Literal["red", "blue"] = "red"
    sizes: Annotated[list[Annotated[int, Field(ge=0)]], Field(min_length=1), "a non-empty list of sizes >= 0"] = [1]


class Form(Section):
    title: Annotated[str, "a string"]
    items: Annotated[list[Item], "an array of tables ([[items]])"] = []
    table: Annotated[dict[str, Literal["a", "b"]], "a table of name = a or b"] = {}
    keyed: Annotated[dict[Literal["x", "y"], Any], "a table of x or y = value"] = {}
    count: Annotated[int, AfterValidator(_even), "an even integer"] | None = None
    sub: Item | None = None


@pytest.mark.parametrize(
    "data, key, what",
    [
        ({"title": "t", "titel": "u"}, "titel", "unknown key; allowed keys: title, items, table, keyed, count, sub"),
        ({}, "title", "missing"),
        ({"title": 1}, "title", "must be a string, got 1"),
        ({"title": "t", "items": [{"name": "a"}, {"nmae": "b"}]}, "items[1].nmae", "unknown key; allowed keys: name,"),
        ({"title": "t", "items": [{"name": "a", "colour": "green"}]}, "items[0].colour", "'green' is not allowed; "),
        (
            {"title": "t", "items": [{"name": "a", "sizes": [1, -2]}]},
            "items[0].sizes",
            "must be a non-empty list of sizes >= 0, got [1, -2]",
        ),
        ({"title": "t", "items": [{"name": "a", "sizes": []}]}, "items[0].sizes", "must be a non-empty list of sizes"),
        ({"title": "t", "items": [3]}, "items[0]", "must be a table, got 3"),
        ({"title": "t", "items": {"name": "a"}}, "items", "must be an array of tables ([[items]]), got {'name': 'a'}"),
        ({"title": "t", "table": {"k": "c"}}, "table.k", "'c' is not allowed; choose one of a, b"),
        ({"title": "t", "keyed": {"z": 1}}, "keyed.z", "unknown key; allowed keys: x, y"),
        ({"title": "t", "count": 3}, "count", "3 is odd; an even number is needed"),
        ({"title": "t", "count": "2"}, "count", "must be an even integer, got '2'"),  # strict: no conversion
        ({"title": "t", "count": True}, "count", "must be an even integer, got True"),
        (
            {"title": "t", "sub": {"name": "s", "extra": 1}},
            "sub.extra",
            "unknown key; allowed keys: name, colour, sizes",
        ),
    ],
)
def test_each_failure_names_the_file_the_key_path_and_what_is_allowed(data, key, what):
    with pytest.raises(FileError) as err:
        check_file("my/file.toml", data, Form)
    assert str(err.value).startswith(f"my/file.toml: key {key!r}: {what}"), str(err.value)
    assert (err.value.key, err.value.path) == (key, "my/file.toml")


def test_an_unknown_key_is_named_before_the_other_failures_and_a_good_file_is_its_model():
    with pytest.raises(FileError, match="key 'oops': unknown key"):
        check_file("f.toml", {"title": 1, "oops": 2}, Form)  # a typo first: the other failures may follow from it
    checked = check_file("f.toml", {"title": "t", "items": [{"name": "a", "sizes": [0, 2]}], "count": 4}, Form)
    assert checked.items[0].sizes == [0, 2] and checked.count == 4 and checked.items[0].colour == "red"


def test_a_file_that_is_not_toml_is_named(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text("[[items]\n")
    with pytest.raises(ValueError, match=rf"^{path}: not valid TOML"):
        read_toml(path)
