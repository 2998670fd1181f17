"""One module writes exploration rows (store/explorations.py): checked on the source of every
module under services/, so a later change cannot quietly write the row somewhere else.

A write is `update(ExplorationRow)`, `insert(ExplorationRow)`, `delete(ExplorationRow)` (or of
its `__table__`, or `insert_for(…, ExplorationRow.__table__)`), an `ExplorationRow(…)`, any
use of `ExplorationRow.__table__` (its `.update()` and `.insert()` are writes too), an
assignment (or `setattr` with the name written out) to an attribute named like one of the
row's columns on anything but `self`, or a raw `UPDATE explorations` / `INSERT INTO
explorations` / `DELETE FROM explorations`. Reads (`select(ExplorationRow…)`,
`row.status == …`, `session.get(ExplorationRow, …)`) are everyone's.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest
from graspscape.services.coordinator.errors import Conflict
from graspscape.services.coordinator.store.explorations import TRANSITIONS, check_transition
from graspscape.services.coordinator.store.models import (
    FINISHED_STATUSES,
    ExplorationRow,
    ExplorationStatus,
)

ROOT = Path(__file__).resolve().parents[4]
SERVICES = ROOT / "services"
OWNER = SERVICES / "coordinator" / "store" / "explorations.py"
COLUMNS = frozenset(ExplorationRow.__table__.c.keys())
_STATEMENTS = frozenset({"update", "insert", "delete", "insert_for"})
_RAW = re.compile(r"\b(UPDATE|INSERT\s+INTO|DELETE\s+FROM)\s+explorations\b", re.IGNORECASE)


def _called(node: ast.Call) -> str | None:
    func = node.func
    return func.id if isinstance(func, ast.Name) else (
        func.attr if isinstance(func, ast.Attribute) else None)


def _names_of_the_model(tree: ast.AST) -> set[str]:
    """ExplorationRow and whatever an import renames it to."""
    names = {"ExplorationRow"}
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            names.update(a.asname for a in node.names if a.name == "ExplorationRow" and a.asname)
    return names


def writes(source: str, name: str = "<source>") -> list[str]:
    """Each write of an exploration row in `source`, as 'line: what'."""
    tree = ast.parse(source, name)
    model = _names_of_the_model(tree)

    def is_model(node: ast.AST) -> bool:
        return (isinstance(node, ast.Name) and node.id in model) or (
            isinstance(node, ast.Attribute) and node.attr == "__table__" and is_model(node.value))

    found: list[str] = []
    for node in ast.walk(tree):
        line = getattr(node, "lineno", 0)
        if isinstance(node, ast.Call):
            called = _called(node)
            if called in model:
                found.append(f"{line}: {called}(…) makes a row")
            elif called in _STATEMENTS and any(is_model(a) for a in node.args):
                found.append(f"{line}: {called}({ast.unparse(node.args[0])}…)")
            elif (called == "setattr" and len(node.args) >= 2
                  and isinstance(node.args[1], ast.Constant) and node.args[1].value in COLUMNS
                  and not (isinstance(node.args[0], ast.Name) and node.args[0].id == "self")):
                found.append(f"{line}: setattr(…, {node.args[1].value!r}, …)")
        elif isinstance(node, ast.Attribute) and node.attr == "__table__" and is_model(node):
            found.append(f"{line}: {ast.unparse(node)}")
        elif (isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store)
              and node.attr in COLUMNS
              and not (isinstance(node.value, ast.Name) and node.value.id == "self")):
            found.append(f"{line}: {ast.unparse(node)} = …")
        elif (isinstance(node, ast.Constant) and isinstance(node.value, str)
              and _RAW.search(node.value)):
            found.append(f"{line}: raw SQL {_RAW.search(node.value).group(0)!r}")
    return sorted(set(found), key=lambda w: int(w.split(":")[0]))


def writers(services: Path, owner: Path) -> list[str]:
    """'module line: what' for each write of an exploration row outside `owner`."""
    found = []
    for path in sorted(services.rglob("*.py")):
        if path != owner:
            found += [f"{path.relative_to(services.parent)} {w}"
                      for w in writes(path.read_text(), str(path))]
    return found


def test_only_store_explorations_writes_exploration_rows() -> None:
    assert writers(SERVICES, OWNER) == [], (
        "write exploration rows through services/coordinator/store/explorations.py")
    assert len(writes(OWNER.read_text())) >= 10  # the owner's own writes are seen


def test_the_reader_sees_each_kind_of_write_and_lets_reads_be() -> None:
    # The check must be able to fail: a module written like an offender is seen as one.
    source = (
        "from m import ExplorationRow as Exp\n"
        "def f(session, row, ids):\n"
        "    session.execute(update(Exp).where(Exp.id == 1).values(status='done'))\n"
        "    session.execute(sa.insert(ExplorationRow), [{}])\n"
        "    session.add(ExplorationRow(object_id=1))\n"
        "    row.manifolds_final = True\n"
        "    row.poses_done += 1\n"
        "    a, row.finished_at = 1, None\n"
        "    setattr(row, 'status', 'cancelled')\n"
        "    ExplorationRow.__table__.delete()\n"
        "    session.execute(text('update explorations set status = 1'))\n"
        "    session.execute(delete(ExplorationRow))\n"
    )
    assert [int(w.split(":")[0]) for w in writes(source)] == [3, 4, 5, 6, 7, 8, 9, 10, 11, 12]
    reads = (
        "def g(session, row):\n"
        "    session.get(ExplorationRow, 1)\n"
        "    session.execute(select(ExplorationRow.status).where(ExplorationRow.id == 1))\n"
        "    session.execute(update(TileRow).where(TileRow.exploration_id == ExplorationRow.id))\n"
        "    done = row.status == 'done' and row.poses_done > 0\n"
        "    self.status = 'mine'\n"
        "    other.lease_owner = None\n"
        "    return 'SELECT * FROM explorations'\n"
    )
    assert writes(reads) == []


def test_the_status_moves_refused_are_those_no_caller_makes() -> None:
    assert set(TRANSITIONS) == set(ExplorationStatus)
    assert TRANSITIONS[ExplorationStatus.CANCELLED] == frozenset()
    for finished in FINISHED_STATUSES:
        with pytest.raises(Conflict, match=f"exploration 7 cannot go from {finished.value} to"):
            check_transition(7, finished.value, ExplorationStatus.CANCELLED)
    with pytest.raises(Conflict):
        check_transition(7, "cancelled", ExplorationStatus.RUNNING)
    for status in (ExplorationStatus.QUEUED, ExplorationStatus.RUNNING,
                   ExplorationStatus.DONE, ExplorationStatus.INCOMPLETE, ExplorationStatus.FAILED):
        check_transition(7, status.value, ExplorationStatus.RUNNING)  # reopened or started
