"""Registries: one name table per pluggable kind, and the one way plugins join it.

Each kind (commands, ``bench`` actions, model runtimes, depth sources, scene sources, exploration
methods) has one :class:`Registry`: the built-in entries, name -> object (a factory, a class or a
command module, one signature per kind, which its module documents), and optionally the entry
point group of ``pyproject.toml`` through which other packages (``datagen``, ``train``,
``deploy``, a user's own) add entries, so the library never imports them:

==========================  ========================  =========================================
kind                        group                     registry
==========================  ========================  =========================================
command                     ``frontiernet.commands``  ``frontiernet.cli.main.COMMANDS``
bench action                ``frontiernet.bench``     ``frontiernet.cli.bench.BENCH_ACTIONS``
model runtime (by suffix)   ``frontiernet.runtimes``  ``frontiernet.model.predictor.RUNTIMES``
exploration method          ``frontiernet.methods``   ``frontiernet.exploration.methods.METHODS``
depth source                none (built in)           ``frontiernet.depth.DEPTH_SOURCES``
scene source                none (built in)           ``frontiernet.scenes.spec.SCENE_SOURCES``
==========================  ========================  =========================================

Entry points are read when names are asked for and loaded (imported) only when one is used. A
built-in entry wins over a plugin of the same name.
"""

from __future__ import annotations

import logging
from typing import Any, Mapping

from .errors import InputError


class Registry:
    """The entries of one pluggable kind: built-in ones and those of one entry point group.

    Args:
        kind: what an entry is, as error messages name it (``"depth source"``).
        group: the entry point group plugins register under (None: built-in entries only).
        builtin: name -> entry, in the order names are listed.
    """

    def __init__(self, kind: str, group: str | None = None, builtin: Mapping[str, Any] | None = None) -> None:
        self.kind, self.group = kind, group
        self.builtin = dict(builtin or {})

    def plugins(self) -> dict:
        """The group's entry points not shadowed by a built-in entry, name -> ``EntryPoint``
        (read now, not loaded; empty without a group)."""
        if self.group is None:
            return {}
        from importlib.metadata import entry_points

        return {entry.name: entry for entry in entry_points(group=self.group) if entry.name not in self.builtin}

    def names(self) -> list[str]:
        """Every name: the built-in ones in their order, then the plugins' sorted."""
        return [*self.builtin, *sorted(self.plugins())]

    def __contains__(self, name: str) -> bool:
        return name in self.builtin or name in self.plugins()

    def get(self, name: str, label: str | None = None):
        """The entry `name` (a plugin's is imported now).

        Args:
            label: how the one-line error names what was asked for (None: the kind), e.g.
                ``"model.onnx: model format"``.
        Raises:
            InputError: an unknown name: "<kind> '<name>' is unknown; valid: <every name>".
        """
        if name in self.builtin:
            return self.builtin[name]
        plugins = self.plugins()
        if name not in plugins:
            raise InputError(f"{label or self.kind} '{name}' is unknown; valid: {', '.join(self.names())}")
        return plugins[name].load()

    def load_all(self) -> list:
        """Every entry, built-in ones first, then the plugins by name. A plugin that fails to
        load is left out with a warning: one broken package must not take the others down."""
        entries = list(self.builtin.values())
        for name, entry in sorted(self.plugins().items()):
            try:
                entries.append(entry.load())
            except Exception as error:  # noqa: BLE001 - any import error of someone else's package
                logging.getLogger(__name__).warning("%s '%s' (%s) failed to load: %s", self.kind, name, entry.value,
                                                    error)
        return entries


__all__ = ["Registry"]
