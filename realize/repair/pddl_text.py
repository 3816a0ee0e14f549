"""Reading a PDDL problem or domain as text: the sections, the facts, the typed objects, the
predicates (for the re-sequence, which rewrites a problem's ``:init``).

What it does: ``strip_comments``, ``section(text, head)`` (start and end of the s-expression
that begins with ``(head``), ``facts(init)`` (the facts of an ``:init`` section as tuples),
``typed_objects(text)`` (``:objects`` as {name: type}), ``domain_predicates(path)``.
What it doesn't: plan (``realize.tasks.pddl``) or read a world.
"""

from __future__ import annotations

import re
from pathlib import Path

from realize.config import ConfigError

__all__ = ["strip_comments", "section", "facts", "typed_objects", "domain_predicates"]


def strip_comments(text: str) -> str:
    return "\n".join(line.split(";", 1)[0] for line in text.splitlines())


def section(text: str, head: str) -> tuple[int, int]:
    """Start and end (exclusive) of the s-expression that begins with ``(head``."""
    m = re.search(r"\(\s*" + re.escape(head) + r"\b", text, re.IGNORECASE)
    if m is None:
        raise ConfigError(f"the PDDL problem has no ({head} ...) section")
    depth, i = 0, m.start()
    while i < len(text):
        depth += text[i] == "("
        depth -= text[i] == ")"
        i += 1
        if depth == 0:
            return m.start(), i
    raise ConfigError(f"the PDDL problem's ({head} ...) section is not closed")


def facts(init: str) -> list[tuple[str, ...]]:
    body = init[init.index("(") + 1: init.rindex(")")]
    body = re.sub(r"^\s*:init", "", body, flags=re.IGNORECASE)
    return [tuple(f.split()) for f in re.findall(r"\(([^()]*)\)", body)]


def domain_predicates(domain: str | Path) -> set[str]:
    """The predicate names (casefolded) the PDDL domain file ``domain`` declares."""
    text = strip_comments(Path(domain).read_text())
    if re.search(r"\(\s*:predicates\b", text, re.IGNORECASE) is None:
        return set()
    lo, hi = section(text, ":predicates")
    return {n.casefold() for n in re.findall(r"\(\s*([^\s()?]+)", text[lo + 1:hi])} - {":predicates"}


def typed_objects(text: str) -> dict[str, str]:
    """The problem's ``:objects`` as {name: type} (``object`` where untyped), both casefolded."""
    lo, hi = section(text, ":objects")
    body = re.sub(r"^\(\s*:objects", "", text[lo:hi - 1], flags=re.IGNORECASE).split()
    out: dict[str, str] = {}
    names: list[str] = []
    i = 0
    while i < len(body):
        if body[i] == "-" and i + 1 < len(body):
            out.update({n.casefold(): body[i + 1].casefold() for n in names})
            names, i = [], i + 2
            continue
        names.append(body[i])
        i += 1
    out.update({n.casefold(): "object" for n in names})
    return out
