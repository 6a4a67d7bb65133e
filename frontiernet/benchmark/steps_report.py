"""The report's "Where the steps go" (:mod:`frontiernet.exploration.steps`): per method, the mean
share of the step budget in each category of the runs' step accounts, the premature stops and the
unseen reachable volume at the end.

A run's account is in its ``metrics.json`` record (``step_account``, ``unseen_reachable``,
``premature_stop``); :func:`account_fields` flattens it into its result row (``steps_<category>``
columns of ``results.csv``). Records written before the account existed (older packs, the
published benchmark) have none: their rows are counted as runs without account and left out of the
means. A report none of whose runs has an account has no such section and no such columns, so it
reads as before the account existed.
"""

from __future__ import annotations

import numpy as np

from ..exploration.steps import CATEGORIES

STEP_COLUMNS = tuple(f"steps_{name}" for name in CATEGORIES)
ACCOUNT_COLUMNS = (*STEP_COLUMNS, "premature_stop", "unseen_reachable")
"""results.csv's columns of a run's account (steps per category, the premature flag, the unseen
reachable fraction), after the others, when some run has an account."""
TITLES = {"start_turn": "start turn", "look_around": "look around", "turn": "turn", "move_new": "move, new",
          "move_none": "move, nothing new", "revisit": "revisit", "livelock": "livelock",
          "unused_premature": "unused, premature", "unused_done": "unused, done"}


def account_fields(record: dict) -> dict:
    """A run's account as flat row fields (:data:`ACCOUNT_COLUMNS`) from its ``metrics.json``
    `record`; {} when the record has no account (or a malformed one)."""
    account = record.get("step_account")
    if not isinstance(account, dict) or not all(isinstance(account.get(name), int) for name in CATEGORIES):
        return {}
    return {**{f"steps_{name}": account[name] for name in CATEGORIES},
            "premature_stop": bool(record.get("premature_stop")), "unseen_reachable": record.get("unseen_reachable")}


def has_account(row: dict) -> bool:
    """Whether a result row carries a step account (numbers in every ``steps_<category>`` column)."""
    return all(_number(row.get(column)) is not None for column in STEP_COLUMNS)


def account_columns(rows: list[dict]) -> list[str]:
    """The account's results.csv columns: :data:`ACCOUNT_COLUMNS` when some row has an account, else none."""
    return list(ACCOUNT_COLUMNS) if any(has_account(row) for row in rows) else []


def _number(value) -> float | None:
    """A row field as a float (rows read back from results.csv hold strings); None when absent or empty."""
    if value is None or value == "" or isinstance(value, bool):
        return None
    try:
        return float(value)
    except (TypeError, ValueError):
        return None


def _premature(row: dict) -> bool:
    return str(row.get("premature_stop")) == "True"


def _shares(runs: list[dict]) -> list[str]:
    """Mean % of the budget per category over `runs` (each with an account), one cell each."""
    cells = []
    for column in STEP_COLUMNS:
        shares = [_number(row[column]) / sum(_number(row[c]) for c in STEP_COLUMNS) for row in runs]
        cells.append(f"{100.0 * np.mean(shares):.1f}")
    return cells


def steps_markdown(done: list[dict], methods: list[str]) -> list[str]:
    """"Where the steps go": per method, over its finished runs (`done`) with an account, the mean
    share (%) of the step budget in each category (a run's categories sum to its budget), the runs
    that stopped prematurely and the mean unseen reachable fraction (%) at the end; runs without an
    account are counted in their own column and left out of the means. No section unless some run
    of `done` has an account."""
    if not any(has_account(row) for row in done):
        return []
    lines = ["### Where the steps go", "",
             "Mean share of the step budget (%) per category of the runs' step accounts (frontiernet/exploration/"
             "steps.py): turns on the spot (start turn, look around without a goal, turns towards a goal), moves "
             "that saw new volume, moves that saw none (elsewhere, or over cells left before: revisit), livelock "
             "(windows with no gain in a small area, frontiers listed) and the budget left unused by a run that "
             "stopped early (premature: \"no frontiers left\" with more than the threshold of the explorable "
             "volume unseen and reachable). Premature stops are counted; unseen reachable is the mean unseen "
             "fraction of the explorable volume in the reachable columns at the end.", "",
             "| method | runs | without account | " + " | ".join(TITLES[name] for name in CATEGORIES)
             + " | premature stops | unseen reachable (%) |",
             "| --- | --- | --- |" + " --- |" * len(CATEGORIES) + " --- | --- |"]
    for method in methods:
        runs = [row for row in done if row["method"] == method]
        counted = [row for row in runs if has_account(row)]
        if not counted:
            cells = ["--"] * (len(CATEGORIES) + 2)
        else:
            unseen = [v for v in (_number(row.get("unseen_reachable")) for row in counted) if v is not None]
            cells = [*_shares(counted), str(sum(_premature(row) for row in counted)),
                     f"{100.0 * np.mean(unseen):.1f}" if unseen else "--"]
        lines.append(f"| {method} | {len(runs)} | {len(runs) - len(counted)} | " + " | ".join(cells) + " |")
    return lines + [""]


__all__ = ["steps_markdown", "account_fields", "account_columns", "has_account", "ACCOUNT_COLUMNS", "STEP_COLUMNS"]
