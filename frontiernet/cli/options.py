"""Options that several ``frontiernet`` commands take with one meaning, each declared here once:
its flag, metavar, default and help text.

A command's ``add_parser`` calls these where it would call ``parser.add_argument`` (an argument
group works as well), in the order its help lists its options; the commands of packages built on
the library (``datagen``, ``train``, ``deploy``) call them too. Options whose meaning is the
command's own are declared in its module.
"""

from __future__ import annotations

import argparse
import re
from pathlib import Path

from ..errors import InputError

SCENE_HELP = "scene spec (see `frontiernet scene --help`)"
"""Help of a command's one scene (``render SPEC``, ``explore --scene SPEC``)."""
MODEL_FILE_HELP = "model file (.safetensors) or checkpoint (.ckpt)"
"""Help of a torch model a command reads (``export MODEL``, ``evaluate MODEL``)."""
EXPLORE_CONFIG = ("configs/explore.yaml, and sim.yaml, depth.yaml and scenes.yaml under sections sim:, depth: "
                  "and scenes:")
"""What ``--config`` overrides in the commands that explore (``explore``, ``bench --scenes``): the files
of :func:`~frontiernet.exploration.run.load_run_config`."""


def option_defaults(actions, skip=()) -> dict:
    """``{dest: (flag, default)}`` of the options (flags, not positionals) among argparse `actions` (a
    parser's ``_actions`` or a group's ``_group_actions``), but ``help`` and the dests in `skip`, each
    with its longest flag: what :func:`given_options` compares a parsed namespace with."""
    return {action.dest: (max(action.option_strings, key=len), action.default) for action in actions
            if action.option_strings and action.dest != "help" and action.dest not in skip}


def given_options(namespace, defaults: dict) -> list[str]:
    """The flags of the options of `defaults` (:func:`option_defaults`) that `namespace` holds another
    value for: the options a user gave where they would be ignored (``bench --report --methods``,
    ``datagen --scenes S preview``), to be refused by name."""
    return [flag for dest, (flag, default) in defaults.items() if getattr(namespace, dest, default) != default]


class Subcommands(argparse._SubParsersAction):
    """The subcommands of a command that has options of its own (``datagen``'s actions, ``bench``'s hot-path
    benchmarks): notes in ``args.options_before_action`` the command's own options (``own_option_defaults``,
    :func:`option_defaults`) given before the subcommand's name, each with the subcommand's option of that name
    or one spelt close to it (None: none): the subcommand drops them (its own option of the same name replaces
    the value), so :func:`options_before_subcommand` names them to be refused."""

    def __call__(self, parser, namespace, values, option_string=None):
        import difflib

        given = given_options(namespace, getattr(namespace, "own_option_defaults", {}))
        chosen = self._name_parser_map.get(values[0])
        taken = sorted(flag for action in (chosen._actions if chosen else ()) for flag in action.option_strings
                       if flag.startswith("--"))
        super().__call__(parser, namespace, values, option_string)
        namespace.options_before_action = [
            (flag, flag if flag in taken else next(iter(difflib.get_close_matches(flag, taken, n=1, cutoff=0.8)), None))
            for flag in given]


def options_before_subcommand(args, command: str) -> str | None:
    """What is wrong with the options of ``frontiernet <command>`` given before its subcommand ``args.action``
    (:class:`Subcommands`), or None when none was: ``--scenes applies to `frontiernet datagen` itself, not to
    `datagen preview```, with the subcommand's own option of that name to give after it instead."""
    given = getattr(args, "options_before_action", [])
    if not given:
        return None
    flags = "/".join(flag for flag, _ in given)
    same = [flag for flag, own in given if own == flag]  # the subcommand's own: given after its name
    close = [f"{own} (not {flag})" for flag, own in given if own not in (None, flag)]
    after = [*same, *close]
    return (f"{flags} appl{'ies' if len(given) == 1 else 'y'} to `frontiernet {command}` itself, not to "
            f"`{command} {args.action}`" + (f" (give {'/'.join(after)} after `{args.action}`)" if after else ""))


class Once(argparse.Action):
    """An option given at most once: a second one is refused (argparse would keep the last one and
    drop the first without a word)."""

    def __call__(self, parser, namespace, values, option_string=None) -> None:
        given = getattr(namespace, self.dest, None)
        if given is not None:
            parser.error(f"{option_string} given twice ({given}, then {values}): give one (put the keys of "
                         f"both in one file, or set some as KEY=VALUE)")
        setattr(namespace, self.dest, values)


def config_file(parser, overriding: str) -> None:
    """``--config FILE``: a YAML file whose keys replace the shipped config's; `overriding` says
    which files and sections it overrides (``configs/train.yaml (and model.*)``). One only (:class:`Once`)."""
    parser.add_argument("--config", metavar="FILE", action=Once, type=input_path("config file"),
                        help=f"YAML overriding {overriding} (one file)")


def config_overrides(parser, example: str, *, option: bool = False) -> None:
    """``KEY=VALUE ...``: dotted config keys set over the config and ``--config`` (`example`: a few
    for the help). Positional words (``args.overrides``), or with `option` the words after
    ``--set`` (``args.set``, default none): a command with subcommands takes them so, as a
    positional list would take the subcommand's name."""
    text = f"config overrides, e.g. {example}"
    if option:
        parser.add_argument("--set", nargs="*", action="extend", default=[], metavar="KEY=VALUE",
                            help=text + " (--set given twice: both lists)")
    else:
        parser.add_argument("overrides", nargs="*", metavar="KEY=VALUE", help=text)


def refuse_contradictions(overrides, options: dict) -> None:
    """InputError where an option and the config key it sets are both given, with other values: `options`
    maps a dotted key to (the option as typed, e.g. ``--seed 1``, and its value; None where not given), and
    a ``KEY=VALUE`` of `overrides` setting that key to another value (read as YAML) contradicts it. Without
    it one of the two was ignored without a word (``--seed 1 run.seed=2`` ran seed 1). Names of one thing
    count as one value: a depth source's alias (``--depth gt run.depth=ground_truth``; the key ``run.depth``)."""
    import yaml

    from ..depth import depth_source_name

    same = {"run.depth": depth_source_name}  # key -> its values' canonical name
    for item in overrides or ():
        key, _, text = str(item).partition("=")
        flag, value = options.get(key.strip(), (None, None))
        if value is None:
            continue
        try:
            given = yaml.safe_load(text)
        except yaml.YAMLError:
            given = text.strip()
        canonical = same.get(key.strip(), str)
        if canonical(str(given)) != canonical(str(value)):
            raise InputError(f"{flag} contradicts {str(item).strip()}: give one of them")


def output_path(text: str) -> str:
    """The argparse type of an output path (``--out``, ``--json FILE``): a blank one is refused, as it names
    the current folder (``Path('')`` is ``.``), which a command would write in or advise ``--force`` for."""
    if not text.strip():
        raise argparse.ArgumentTypeError(f"an empty path ({text!r}) names no output; give a folder or file name "
                                         "(the current folder is '.')")
    return text


def input_path(what: str):
    """The argparse type of an option naming an input file or folder (`what`: ``config file``, ``dataset
    folder``): an empty path is refused (:func:`~frontiernet.io.nonempty_path`), as ``Path('')`` is ``.``,
    which a command would read as the current folder (``.: is a folder, expected a file``)."""
    def check(text: str) -> str:
        from ..io import nonempty_path

        try:
            nonempty_path(text, what)
        except InputError as error:
            raise argparse.ArgumentTypeError(str(error)) from None
        return text

    return check


_OVERRIDE = re.compile(r"[A-Za-z_][\w-]*(\.[\w-]+)*=.*")
"""A word that reads as a ``KEY=VALUE`` config override."""


def optional_input_path(what: str, flag: str):
    """The argparse type of an option whose value may be left out (``--resume [CKPT]``, ``--show-prediction
    [PREDICTOR]``): :func:`input_path`, and a word that reads as a ``KEY=VALUE`` config override and is no file
    is refused as the override it is, which `flag` took for its value (``--resume optim.lr=0.1`` was
    "optim.lr=0.1: checkpoint to resume from not found"). A model file's name (``epoch=3-step=9.ckpt``) is no
    override."""
    check = input_path(what)

    def take(text: str) -> str:
        text = check(text)
        if _OVERRIDE.fullmatch(text) and not Path(text).exists() and \
                Path(text).suffix.lower() not in (".ckpt", ".safetensors", ".pt", ".onnx"):
            raise argparse.ArgumentTypeError(f"took the config override {text} for its {what}; give the overrides "
                                             f"before {flag} (or a {what} after it)")
        return text

    return take


def output_folder(parser, *, force: bool = False, default: str | None = None) -> None:
    """``--out DIR``, the folder a command writes (required unless it has a `default`), and with
    `force` ``--force``, which a command checks with :func:`~frontiernet.io.check_output_folder`."""
    parser.add_argument("--out", metavar="DIR", type=output_path, required=default is None, default=default,
                        help="output folder" + (f" (default {default})" if default else ""))
    if force:
        parser.add_argument("--force", action="store_true",
                            help="write over earlier outputs in --out (refused without it)")


def output_file(parser, what: str = "output file") -> None:
    """``--out FILE`` (required; `what` is its help) and ``--force``, which a command checks with
    :func:`~frontiernet.io.check_output_file`."""
    parser.add_argument("--out", metavar="FILE", type=output_path, required=True, help=what)
    parser.add_argument("--force", action="store_true", help="replace --out if it exists (refused without it)")


def json_only(parser) -> None:
    """``--json``: print the result as one JSON object instead of the report."""
    parser.add_argument("--json", action="store_true", help="print JSON only")


def json_file(parser, what: str) -> None:
    """``--json FILE``: also write the result (`what`, e.g. ``the metrics``) as JSON there."""
    parser.add_argument("--json", metavar="FILE", type=output_path, help=f"also write {what} as JSON")


def no_progress(parser) -> None:
    """``--no-progress``: no progress bar (logs, batch jobs)."""
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def model_file(parser) -> None:
    """``MODEL``: the torch model a command reads (positional, required)."""
    parser.add_argument("model", metavar="MODEL", type=input_path("model file"), help=MODEL_FILE_HELP)


def model_option(parser, *, exports: bool = True, what: str = "model file") -> None:
    """``--model``: the FrontierNet model to run (default: the shipped one); with `exports` the
    exported files of ``frontiernet export`` too. `what` names it (``model file of the learned
    methods``)."""
    files = ".safetensors, .ckpt, .onnx, .pt" if exports else ".safetensors, .ckpt"
    parser.add_argument("--model", type=input_path(what), help=f"{what} ({files}; default: the shipped model)")


def scene_world(parser, uses: str) -> None:
    """``SPEC`` (``args.spec``) and ``--config FILE``: the scene a command builds with
    :func:`~frontiernet.simulator.world.build_world`, and a YAML file over the config it reads
    (:func:`~frontiernet.simulator.world.load_world_config`: sim.yaml, and scenes.yaml as section
    ``scenes``); `uses` says which of sim.yaml's settings the command uses (``camera, voxels``)."""
    parser.add_argument("spec", metavar="SPEC", help=SCENE_HELP)
    config_file(parser, f"configs/sim.yaml ({uses}), and scenes.yaml under section scenes:")


def scene_specs(parser, *, required: bool = False) -> None:
    """``--scenes SPEC ...``: many scenes (:func:`~frontiernet.scenes.spec.expand_specs` expands them)."""
    parser.add_argument("--scenes", nargs="+", required=required, metavar="SPEC",
                        help="scene specs: files, hm3d:/floorplan: folders, procedural:SEED, seed ranges "
                             "procedural:0-199, quoted globs, folders of scene folders")


def benchmark_scene(parser) -> None:
    """``--scene``: the scene a hot-path benchmark times (:func:`~frontiernet.benchmark.perf.default_bench_scene`)."""
    parser.add_argument("--scene", default=None,
                        help="scene spec (default: perf.scene of configs/bench.yaml, the shared house next to "
                             "the checkout, when present; else perf.fallback_scene)")


def parallel(parser) -> None:
    """``--workers W --backend local|ray``: how a command runs its tasks
    (:func:`~frontiernet.workers.run_parallel`, which checks both with
    :func:`~frontiernet.workers.check_backend` before anything is written)."""
    parser.add_argument("--workers", type=int, default=1, help="parallel worker processes or Ray tasks (default 1)")
    parser.add_argument("--backend", default="local",
                        help="local (processes, the default) or ray (Ray tasks; set RAY_ADDRESS to use a cluster)")


def dataset_run(parser) -> None:
    """``--seed S --resume``: a dataset generator's run seed and the continuation of its ``--out``
    (``datagen``, ``mapgen``)."""
    parser.add_argument("--seed", type=int, default=0, help="run seed: same seed, same bytes (default 0)")
    parser.add_argument("--resume", action="store_true", help="continue the dataset in --out")


def max_steps(parser, config: str) -> None:
    """``--max-steps``: an exploration's step budget, by default ``run.max_steps`` of `config`."""
    parser.add_argument("--max-steps", type=int, help=f"step budget (default: {config} run.max_steps)")
