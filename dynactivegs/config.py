"""Frozen configuration dataclasses: one per stage, the simulator's, the top-level :class:`DagsConfig`
and the named presets of the paper's ablations.

Each field has a docstring underneath it; ``tyro`` turns these into ``--help`` text. Values are
checked on construction and a bad one raises :class:`ConfigError` naming the field, the value
and the allowed range. :func:`with_overrides` applies ``key=value`` strings
(``mapping.weighted=false``) as used by ``dagsreplay --set``.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field

from dynactivegs.errors import ConfigError, check_config
from dynactivegs.fields.grid import FieldsConfig
from dynactivegs.mapping.config import MappingConfig
from dynactivegs.perception.config import FeatureConfig, PerceptionConfig, UncertaintyConfig
from dynactivegs.planning.paths import PathConfig
from dynactivegs.planning.stage import PlanningConfig
from dynactivegs.selection.stage import SelectionConfig
from dynactivegs.sim.config import CameraConfig, CrowdConfig, RobotConfig, SimConfig

__all__ = ["CameraConfig", "CrowdConfig", "DagsConfig", "FeatureConfig", "FieldsConfig", "MappingConfig",
           "PerceptionConfig", "PlanningConfig", "PRESETS", "RobotConfig", "SelectionConfig", "SimConfig",
           "UncertaintyConfig", "check_consistent", "config_value", "preset", "to_json", "with_overrides"]


@dataclass(frozen=True, slots=True)
class DagsConfig:
    """Everything a run needs: the seed and one config per component."""

    seed: int = 0
    """Master seed; every random choice in a run derives from it."""
    sim: SimConfig = field(default_factory=SimConfig)
    perception: PerceptionConfig = field(default_factory=PerceptionConfig)
    mapping: MappingConfig = field(default_factory=MappingConfig)
    fields: FieldsConfig = field(default_factory=FieldsConfig)
    selection: SelectionConfig = field(default_factory=SelectionConfig)
    planning: PlanningConfig = field(default_factory=PlanningConfig)

    def __post_init__(self) -> None:
        check_config(0 <= self.seed < 2**63, "seed", self.seed, "in [0, 2^63)")


def _preset(weighted: bool, selection: str, planner: str) -> DagsConfig:
    return DagsConfig(mapping=MappingConfig(weighted=weighted), selection=SelectionConfig(variant=selection),
                      planning=PlanningConfig(path=PathConfig(variant=planner)))


PRESETS: dict[str, DagsConfig] = {
    # the paper's component ablation (Table 3)
    "baseline": _preset(False, "gain_cost", "shortest"),        # no weighted mapping, static-gain view selection
    "weighted": _preset(True, "gain_cost", "shortest"),         # + uncertainty-weighted mapping
    "motion_view": _preset(True, "full", "shortest"),           # + motion-aware view selection
    "full": _preset(True, "full", "dyn_edge_temporal"),         # + motion-aware planning: the method
    # classic nearest-frontier exploration with the method's mapping
    "frontier": _preset(True, "frontier", "shortest"),
    # view-selection variants (Table 4), the rest as in full
    "sel_random": _preset(True, "random", "dyn_edge_temporal"),
    "sel_static_gain": _preset(True, "static_gain", "dyn_edge_temporal"),
    "sel_gain_cost": _preset(True, "gain_cost", "dyn_edge_temporal"),
    # planner variants (Table 5), the rest as in full
    "plan_shortest": _preset(True, "full", "shortest"),
    "plan_dyn_edge": _preset(True, "full", "dyn_edge"),
}


ROBOT_KEYS: tuple[tuple[str, str, tuple[str, ...]], ...] = (
    # (what the simulator's robot has, how the stages' copies must relate to it, the copies)
    ("sim.robot.forward_step_m", "==", ("planning.actions.forward_step_m", "selection.forward_step_m")),
    ("sim.robot.turn_step_deg", "==", ("planning.actions.turn_step_deg",)),
    ("sim.robot.radius_m", ">=", ("planning.actions.radius_m", "selection.voronoi.robot_radius_m")),
    ("sim.robot.body_height_m", ">=", ("planning.actions.band_hi_m", "selection.occupancy.band_hi_m")),
    ("sim.camera.height_m", "==", ("selection.visibility.camera_height_m",)),
    ("selection.reach_tol_m", "<=", ("planning.actions.target_tol_m",)),
    ("selection.stuck_steps", "==", ("planning.actions.stuck_steps",)),
    ("selection.stuck_move_tol_m", "==", ("planning.actions.stuck_move_tol_m",)),
)
"""Settings the stages copy from the robot (or from each other), since a stage reads only its own config. ``==``:
the copy must equal the original (the planner's model of one action is the robot's action); ``>=``: the copy may
be more cautious (a planning radius above the body's keeps a margin, one below plans through gaps the body does not
pass); ``<=``: the planner's target tolerance may not exceed the selection's, or the robot stops short of where the
selection counts a target reached and waits there until it gives the target up as stuck."""


def config_value(cfg, key: str) -> object:
    """The value of the dotted ``key`` (``planning.actions.radius_m``) in ``cfg``."""
    for name in key.split("."):
        cfg = getattr(cfg, name)
    return cfg


def check_consistent(cfg: DagsConfig) -> DagsConfig:
    """``cfg`` when every copy of ROBOT_KEYS relates to its original as it must, else a one-line
    :class:`ConfigError` naming both keys and the values to set (a ``--set`` of one of them alone)."""
    ok = {"==": lambda copy, orig: copy == orig, ">=": lambda copy, orig: copy >= orig,
          "<=": lambda copy, orig: copy <= orig}
    for original, rel, copies in ROBOT_KEYS:
        want = config_value(cfg, original)
        for key in copies:
            have = config_value(cfg, key)
            if not ok[rel](have, want):
                fix = " ".join(f"{k}={want}" for k in copies)
                raise ConfigError(f"bad config value {key}={have!r}: must be {rel} {original} ({want}); the stages "
                                  f"keep their own copy of it, so set them together, e.g. --set {original}={want} "
                                  f"{fix}")
    return cfg


def preset(name: str) -> DagsConfig:
    """The named preset; a one-line error lists the names for an unknown one."""
    if name not in PRESETS:
        raise ConfigError(f"unknown preset {name!r}: use one of {', '.join(PRESETS)}")
    return PRESETS[name]


def _parse(value: str, current: object, key: str) -> object:
    try:
        if isinstance(current, bool):
            if value.lower() in ("true", "1", "yes", "on"):
                return True
            if value.lower() in ("false", "0", "no", "off"):
                return False
            raise ValueError
        if isinstance(current, int):
            return int(value)
        if isinstance(current, float):
            return float(value)
    except ValueError:
        raise ConfigError(f"bad value for {key}: {value!r} is not a {type(current).__name__}") from None
    if isinstance(current, str):
        return value
    raise ConfigError(f"{key} is a group, not a value; set one of its fields ({key}.<name>=...)")


def with_overrides(cfg, overrides: list[str] | tuple[str, ...]):
    """A copy of ``cfg`` with ``section.sub.field=value`` strings applied (values parsed by the field's type); a
    :class:`DagsConfig` is checked for settings copied between stages (:func:`check_consistent`) once all are."""
    for item in overrides:
        if "=" not in item:
            raise ConfigError(f"bad override {item!r}: write key=value, e.g. mapping.weighted=false")
        key, value = item.split("=", 1)
        cfg = _set(cfg, key.strip().split("."), value.strip(), key.strip())
    return check_consistent(cfg) if isinstance(cfg, DagsConfig) else cfg


def _set(obj, path: list[str], value: str, key: str):
    names = {f.name for f in dataclasses.fields(obj)}
    if path[0] not in names:
        raise ConfigError(f"unknown config key {key!r}: {type(obj).__name__} has {', '.join(sorted(names))}")
    current = getattr(obj, path[0])
    new = _set(current, path[1:], value, key) if len(path) > 1 else _parse(value, current, key)
    if len(path) > 1 and not dataclasses.is_dataclass(current):
        raise ConfigError(f"unknown config key {key!r}: {path[0]} has no fields")
    return dataclasses.replace(obj, **{path[0]: new})


def to_json(cfg) -> str:
    """The resolved config as JSON (sorted keys; NaN as the string "nan")."""
    def conv(x):
        if dataclasses.is_dataclass(x):
            return {f.name: conv(getattr(x, f.name)) for f in dataclasses.fields(x)}
        if isinstance(x, float) and x != x:
            return "nan"
        if isinstance(x, (tuple, list)):
            return [conv(v) for v in x]
        return x
    return json.dumps(conv(cfg), sort_keys=True)


def config_from_json(text: str, cls: type = DagsConfig):
    """The config that :func:`to_json` wrote (nested dataclasses rebuilt); a one-line error for unknown keys.

    Keys missing from the JSON keep their defaults, so a log written before a field was added
    still loads; a key the dataclass does not have is an error naming it.
    """
    try:
        data = json.loads(text)
    except (TypeError, ValueError) as e:
        raise ConfigError(f"config is not valid JSON: {str(e).splitlines()[0]}") from None
    return _from_dict(cls, data, "")


def _from_dict(cls: type, data: object, where: str):
    import typing

    if not isinstance(data, dict):
        raise ConfigError(f"config {where or 'root'}: expected an object, found {type(data).__name__}")
    hints = typing.get_type_hints(cls)
    names = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - names)
    if unknown:
        raise ConfigError(f"unknown config key {where + unknown[0]!r}: {cls.__name__} has {', '.join(sorted(names))}")
    kwargs = {}
    for f in dataclasses.fields(cls):
        if f.name not in data or not f.init:
            continue
        kwargs[f.name] = _value_from_json(hints[f.name], data[f.name], f"{where}{f.name}")
    try:
        return cls(**kwargs)
    except TypeError as e:
        raise ConfigError(f"config {where or 'root'}: {e}") from None


def _value_from_json(hint: object, v: object, key: str):
    import types
    import typing

    if dataclasses.is_dataclass(hint):
        return _from_dict(hint, v, key + ".")
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(hint) if a is not type(None)]
        if v is None:
            return None
        return _value_from_json(args[0], v, key) if len(args) == 1 else v
    if hint is float:
        if isinstance(v, str) and v.lower() in ("nan", "inf", "-inf"):
            return float(v)
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            return float(v)
    elif hint is int:
        if isinstance(v, int) and not isinstance(v, bool):
            return v
    elif hint is bool:
        if isinstance(v, bool):
            return v
    elif hint is str:
        if isinstance(v, str):
            return v
    elif typing.get_origin(hint) is tuple and isinstance(v, list):
        args = typing.get_args(hint)
        inner = args[0] if args else object
        return tuple(_value_from_json(inner, x, key) for x in v)
    else:
        return v
    raise ConfigError(f"config {key}: {v!r} is not a {getattr(hint, '__name__', hint)}")
