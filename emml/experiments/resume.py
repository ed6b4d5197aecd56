"""How to run a command again: the resume line a stopped `emml run` and `emml campaign` print, and the command a
pinned campaign re-executes from its worktree, spelled in one place."""

from __future__ import annotations

from collections.abc import Iterable, Sequence


def command_line(
    words: Sequence[str], options: Iterable[tuple[str, object]] = (), plugins: Iterable[str] = ()
) -> list[str]:
    """``emml [--plugin P]... WORDS... OPTIONS...`` as argv: the plugins its models need first (`emml --plugin`),
    then each option in order: left out when its value is None, False, 0 or empty (the command's default), a bare
    flag when True, repeated per value when a list or tuple, else ``--option VALUE``."""
    args = ["emml", *[a for p in plugins for a in ("--plugin", p)], *words]
    for option, value in options:
        if not value:  # None, False, 0, "", an empty list or tuple
            continue
        if value is True:
            args.append(option)
        elif isinstance(value, (list, tuple)):
            args += [a for v in value for a in (option, str(v))]
        else:
            args += [option, str(value)]
    return args
