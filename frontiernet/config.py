"""Configuration: YAML files under ``configs/`` merged with user files and overrides.

Every tunable number lives in a YAML file of ``configs/`` (installed as the package
``frontiernet.configs``), with the paper's or the public code's value as default and
a comment saying which. :func:`load_config` reads one of them by name, then merges
an optional user file and ``key.sub=value`` overrides on top.
"""

from __future__ import annotations

from dataclasses import field, fields
from importlib import resources
from pathlib import Path
from typing import ClassVar, Iterable, Mapping, Sequence

from omegaconf import DictConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException

from .config_ranges import Layout, layout_ranges, layout_relations, magnitude_note
from .errors import InputError, check_keys, decode_problem, setting_text


_MISSING = object()


def setting(check, *args, key: str | None = None, each: Sequence[str] = (), **kwargs):
    """A field of a :class:`ConfigSection`: the value of the section's `key` (the field's name
    unless given; dotted: a key of a sub-section) as ``check(value, name, *args, **kwargs)``
    returns it, `name` being ``<SECTION>.<key>``; `check` raises InputError naming it for a bad
    value (``setting(whole_number, 1)``: an integer >= 1, see :mod:`frontiernet.errors`).
    With `each`, the value is a sub-section: a dict of each key of `each`, checked the same way
    under the name ``<SECTION>.<key>.<each key>``."""
    return field(metadata={"check": (check, args, kwargs), "key": key, "each": tuple(each)})


def section_value(section, key: str, where: str):
    """``section[key]``, `key` dotted for a key of a sub-section; `where` names `section`
    (``anchoring``, ``anchoring.feature_weights``). InputError ``<where>.<key> is missing from
    the <config> config`` naming the first part that is missing."""
    value, path = section, where
    for part in key.split("."):
        path = f"{path}.{part}"
        value = value.get(part, _MISSING) if hasattr(value, "get") else _MISSING
        if value is _MISSING:
            raise InputError(f"{path} is missing from the {where.split('.')[0]} config")
    return value


class ConfigSection:
    """Base of the checked, typed settings of one config section: frozen dataclasses such as
    ``MapSettings``, each field declared with :func:`setting`, which says its key and its check.
    :meth:`from_config` takes the settings themselves, the section (an OmegaConf ``DictConfig`` or
    a dict), or a whole config holding it under :attr:`SECTION`, and has :meth:`from_section`
    check and type the section, raising :class:`~frontiernet.errors.InputError` naming the first
    missing or bad key (a subclass's ``__post_init__`` checks what ties keys together)."""

    SECTION: ClassVar[str] = ""

    @classmethod
    def from_config(cls, conf):
        if isinstance(conf, cls):
            return conf
        if not hasattr(conf, "get"):
            raise InputError(f"the {cls.SECTION} config must be a mapping, got {type(conf).__name__}")
        return cls.from_section(conf.get(cls.SECTION, conf))

    @classmethod
    def from_section(cls, section):
        """The settings of `section` (a DictConfig or dict): each field's key read and checked,
        in the order of the fields, as its :func:`setting` says."""
        values = {}
        for spec in fields(cls):
            key = spec.metadata["key"] or spec.name
            check, args, kwargs = spec.metadata["check"]
            value, name = section_value(section, key, cls.SECTION), f"{cls.SECTION}.{key}"
            if spec.metadata["each"]:
                values[spec.name] = {part: check(section_value(value, part, name), f"{name}.{part}", *args, **kwargs)
                                     for part in spec.metadata["each"]}
            else:
                values[spec.name] = check(value, name, *args, **kwargs)
        return cls(**values)


def default_config_path(name: str) -> Path:
    """Path of the shipped config ``configs/<name>.yaml``."""
    path = Path(str(resources.files("frontiernet.configs").joinpath(f"{name}.yaml")))
    if not path.is_file():
        raise InputError(f"no shipped config named '{name}' (looked for {path})")
    return path


def _read_yaml(path: Path) -> DictConfig:
    from .io import check_yaml_mapping, input_file

    input_file(path, "config file")
    import yaml

    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, ValueError) as error:  # (UTF-16, random bytes: "not UTF-8 text", not the decoder's own words)
        raise InputError(f"{path}: not a readable YAML config: {decode_problem(error)}") from None
    try:
        root = yaml.compose(text, Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader))
        if root is None:  # (a config saved empty, or the wrong file, ran as if no --config were given)
            said = "is an empty file (0 bytes)" if not text else "holds no settings (blank lines and comments only)"
            raise InputError(f"{path}: {said}; a config is a YAML mapping of settings (key: value lines)")
        check_yaml_mapping(root, path)
        _check_no_base_60(root, path)
        conf = OmegaConf.load(path)
    except yaml.YAMLError as error:  # malformed YAML: say where
        mark = getattr(error, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        problem = getattr(error, "problem", None) or decode_problem(error)  # (a ReaderError's own words, no class name)
        if "expansion exceeds" in str(problem):  # OmegaConf stopped expanding aliases: not its advice to raise it
            limit = str(problem).split("limit of ")[-1].split(".")[0]
            raise InputError(f"{path}: its YAML aliases (*name) expand past {limit} nodes, more than a config has "
                             "(a YAML bomb?); refused unexpanded: write the values out") from None
        raise InputError(f"{path}: not valid YAML{where} ({problem})") from None
    except InputError:
        raise
    except (OSError, OmegaConfBaseException, ValueError) as error:
        raise InputError(f"{path}: not a readable YAML config ({decode_problem(error)})") from None
    if not isinstance(conf, DictConfig):
        raise InputError(f"{path}: a config must be a YAML mapping")
    return conf


def load_config(
    name: str | Sequence[str],
    user_file: str | Path | None = None,
    overrides: Iterable[str] = (),
) -> DictConfig:
    """Load ``configs/<name>.yaml``, then merge `user_file` and dotted `overrides`.

    Args:
        name: shipped config name, e.g. ``"sim"``, or several names whose files are
            merged in order (``("sim", "datagen")``: datagen's keys win).
        user_file: optional YAML file whose keys replace the defaults.
        overrides: ``"camera.width=320"`` style strings.
    Returns:
        The merged, read-only-by-convention ``DictConfig``.
    """
    names = [name] if isinstance(name, str) else list(name)
    conf = OmegaConf.merge(*[_read_yaml(default_config_path(n)) for n in names])
    return merge_user(conf, user_file, overrides, layout={"": names})


def merge_user(conf: DictConfig, user_file: str | Path | None = None, overrides: Iterable[str] = (), *,
               layout: Layout) -> DictConfig:
    """`conf` with a user YAML file, then ``key.sub=value`` overrides, merged on top. Every key
    they set must exist in `conf` (a typo would otherwise be ignored in silence), except under
    a key whose default is null or an empty mapping (open option sections), and every value must
    be in its declared range (:func:`check_ranges` with `layout`: where `conf`'s shipped files sit)."""
    shipped = conf
    if user_file is not None:
        user = _read_yaml(Path(user_file))
        check_keys(conf, user, str(user_file))
        conf = OmegaConf.merge(conf, user)
    conf = apply_overrides(conf, overrides, shipped)
    check_ranges(conf, layout)
    return conf


def _shown(value) -> str:
    """`value` as a message shows it: :func:`~frontiernet.errors.setting_text` (null for None, as the user typed
    ``~`` or ``null``), a long list by its ends and length (a message stays one short line)."""
    if isinstance(value, (list, tuple)) and len(value) > 8:
        return f"[{', '.join(map(setting_text, value[:3]))}, ..., {setting_text(value[-1])}] ({len(value)} items)"
    return setting_text(value)


def check_ranges(conf, layout: Layout) -> None:
    """InputError naming the first key of `conf` (a DictConfig or plain dict) whose value is outside
    its range declared in ``configs/ranges/`` (:mod:`frontiernet.config_ranges`), e.g.
    ``planner.gain_exponent must be a number >= 0, got -2``, or breaks a declared relation between keys
    (``map.occupied_threshold < map.log_odds_max must hold (...)``; a relation that computes a product or sum
    also shows the numbers compared, ``...: 228,757,340,160 > 10,000,000``). `layout` says where each shipped file's
    keys sit in `conf` (``{"": "explore", "scenes": "scenes"}``); keys `conf` lacks are skipped."""
    tree = OmegaConf.to_container(conf, resolve=True) if isinstance(conf, DictConfig) else conf
    for key, spec in layout_ranges(layout).items():
        parent, leaf = dotted_parent(tree, key)
        if parent is not None and leaf in parent and not spec.admits(parent[leaf]):
            note = magnitude_note(parent[leaf], spec.integer)
            raise InputError(f"{key} must be {spec.describe()}, got {_shown(parent[leaf])}{note}")
    for relation in layout_relations(layout):
        values = {}
        for key in relation.keys():
            parent, leaf = dotted_parent(tree, key)
            values[key] = parent.get(leaf) if parent is not None else None
        if relation.holds(values) is False:
            got = ", ".join(f"{key}={_shown(value)}" for key, value in values.items())
            computed = relation.broken(values)
            raise InputError(f"{relation.text()} must hold ({relation.reason}), got {got}"
                             + (f": {computed}" if computed else ""))


def _refuse_values_set_inside(overrides: list[str]) -> None:
    """InputError for a ``KEY=VALUE`` of a value that is no mapping followed by an override of a key inside KEY
    (``sim.camera=5 sim.camera.width=64``): the later one made KEY a section again, and the value was dropped
    without a word (in the other order the value is refused: KEY takes a section)."""
    import yaml

    for at, item in enumerate(overrides):
        key, _, text = item.partition("=")
        inside = next((other for other in overrides[at + 1:] if other.split("=", 1)[0].strip().startswith(
            key.strip() + ".")), None)
        if inside is None:
            continue
        try:
            value = yaml.safe_load(text)
        except yaml.YAMLError:
            value = text
        if not isinstance(value, dict):
            raise InputError(f"override '{item}' sets {key.strip()} to a value, but '{inside}' after it sets a key "
                             f"inside it (a section): give one of them")


def _is_base_60(node) -> bool:
    """Whether YAML node `node` is a plain scalar that YAML 1.1 reads as a base-60 number (``1:00`` is 60, ``1:30.5``
    is 90.5): nobody means that in a config; the user typed a time or a ratio."""
    import yaml

    return (isinstance(node, yaml.ScalarNode) and not node.style and ":" in node.value  # (plain: None, C loader "")
            and node.tag in ("tag:yaml.org,2002:int", "tag:yaml.org,2002:float"))


def _base_60_as_text(item: str) -> str:
    """``key=value`` override `item`, its value quoted when YAML 1.1 would read it as a base-60 number
    (:func:`_is_base_60`): ``run.max_steps=1:00`` is then the text '1:00', refused as no number by the key's check,
    as ``0:02`` always was (it ran 60 steps)."""
    import yaml

    key, _, value = item.partition("=")
    try:
        node = yaml.compose(value, Loader=yaml.SafeLoader)
    except yaml.YAMLError:
        return item  # (the parse below names it)
    return f"{key}='{value.strip()}'" if _is_base_60(node) else item


def _check_no_base_60(root, path) -> None:
    """InputError naming YAML file `path` and the line of the first plain scalar of the composed tree `root` that
    YAML 1.1 reads as a base-60 number (:func:`_is_base_60`): ``max_steps: 1:00`` ran 60 steps."""
    import yaml

    seen, stack = set(), [root]
    while stack:
        node = stack.pop()
        if node is None or id(node) in seen:
            continue
        seen.add(id(node))
        if _is_base_60(node):
            number = yaml.safe_load(node.value)
            raise InputError(f"{path}: line {node.start_mark.line + 1}: YAML reads {node.value} as the base-60 number "
                             f"{number}; write {number} if that is meant, or quote '{node.value}' as text")
        if isinstance(node, yaml.MappingNode):
            stack += [part for pair in node.value for part in pair]
        elif isinstance(node, yaml.SequenceNode):
            stack += node.value


def _unparsable_override(overrides: list[str], error) -> str:
    """The message for ``key=value`` `overrides` whose values OmegaConf could not read as YAML (`error`, the
    YAMLError it raised): the first item whose value alone is no YAML, named with the parser's own words."""
    import yaml

    def problem(error) -> str:
        words = [getattr(error, "context", None), getattr(error, "problem", None)]
        return ": ".join(str(word) for word in words if word) or str(error).splitlines()[0]

    for item in overrides:
        try:
            yaml.safe_load(item.split("=", 1)[1])
        except yaml.YAMLError as own:
            return f"override '{item}': its value is not valid YAML ({problem(own)})"
    return f"overrides {' '.join(overrides)}: not valid YAML ({problem(error)})"


def apply_overrides(conf: DictConfig, overrides: Iterable[str] = (), shipped: DictConfig | None = None) -> DictConfig:
    """`conf` with ``key.sub=value`` strings merged on top (InputError for a malformed one or a
    key that `conf` does not have, see :func:`merge_user`). A value's kind is judged by the `shipped`
    config's (default `conf`): a user file's 0 for a key that also takes ``auto`` made ``abc`` "takes a
    number (default 0)", the file's value named as the default and ``auto`` left out."""
    overrides = list(overrides)
    if overrides:
        bad = [item for item in overrides if "=" not in item]
        if bad:
            raise InputError(f"override '{bad[0]}' is not of the form key=value")
        # a key given twice: the later wins, as with a command line's repeated flags (scripts/train_on_gpu.sh
        # sets its defaults first and passes the user's key=value after them)
        empty = next((item for item in overrides if not item.split("=", 1)[1].strip()), None)
        if empty is not None:
            key = empty.split("=", 1)[0].strip()
            raise InputError(f"override '{empty}' has no value (write {key}=null for none)")
        _refuse_values_set_inside(overrides)
        import yaml

        overrides = [_base_60_as_text(item) for item in overrides]
        try:
            extra = OmegaConf.from_dotlist(overrides)
        except yaml.YAMLError as error:  # an unclosed [ or quote, a tag, an alias, a tab: name the item
            raise InputError(_unparsable_override(overrides, error)) from None
        except OmegaConfBaseException as error:
            raise InputError(f"bad override {overrides}: {error}") from None
        check_keys(conf if shipped is None else shipped, extra, "override")
        try:
            conf = OmegaConf.merge(conf, extra)
        except OmegaConfBaseException as error:
            raise InputError(f"bad override {overrides}: {error}") from None
    return conf


def dotted_parent(tree: dict, dotted: str) -> tuple[dict | None, str]:
    """The plain nested dict that holds dotted key `dotted` of `tree` (``"a.b.c"``: ``tree["a"]["b"]``)
    and the last key (``"c"``); None for the dict when a section on the way is missing or no dict."""
    *sections, key = dotted.split(".")
    for name in sections:
        tree = tree.get(name) if isinstance(tree, dict) else None
    return (tree if isinstance(tree, dict) else None), key


def differences(old, new, prefix: str = "", before: str = "before"):
    """Every dotted key whose value differs between two nested dicts of settings, in sorted key order, as
    ``(key, "key: OLD in <before>, NEW now")`` (``absent`` for a missing key, :func:`setting_text` for a
    value); `before` names where the old settings are kept (``the plan`` of a benchmark, ``the dataset`` of
    datagen)."""
    if isinstance(old, dict) and isinstance(new, dict):
        for key in sorted(set(old) | set(new), key=str):
            name = f"{prefix}{key}"
            if key not in old or key not in new:
                shown = [setting_text(side[key]) if key in side else "absent" for side in (old, new)]
                yield name, f"{name}: {shown[0]} in {before}, {shown[1]} now"
            else:
                yield from differences(old[key], new[key], f"{name}.", before)
    elif old != new:
        name = prefix.rstrip(".")
        yield name, f"{name}: {setting_text(old)} in {before}, {setting_text(new)} now"


def first_difference(old, new, before: str = "before") -> str | None:
    """The first of :func:`differences` as its text; None when equal."""
    return next((text for _, text in differences(old, new, before=before)), None)


def option_section(conf, options: Sequence[str], where: str) -> dict:
    """`conf`, a section of options (DictConfig or mapping, as the command resolved it), as a plain
    ``dict`` holding every key of `options` and no other.

    Raises:
        InputError: `conf` is not a mapping, or has an unknown key (named with its closest
            spellings: typos fail loudly) or lacks one; `where` (``depth.emulated``) starts the line.
    """
    if isinstance(conf, DictConfig):
        conf = OmegaConf.to_container(conf, resolve=True)
    if not isinstance(conf, Mapping):
        raise InputError(f"{where}: expected a mapping of options, got {type(conf).__name__}")
    check_keys(dict.fromkeys(options), conf, where, noun="option")
    missing = [key for key in options if key not in conf]
    if missing:
        raise InputError(f"{where}: missing option(s) {', '.join(missing)}")
    return dict(conf)
