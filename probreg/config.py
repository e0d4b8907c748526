"""Configuration files: a TOML file holding the options of ``probreg run`` (and of the commands
that share them), as Pose2Sim users keep a ``Config.toml`` per study.

``probreg config > probreg.toml`` writes the commented default; ``probreg run ... --config
probreg.toml`` reads it.  Precedence: a flag given on the command line > the file > the built-in
default.  Unknown keys and values of the wrong type are errors that name the key.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from pathlib import Path

__all__ = ["CONFIG_KEYS", "ConfigError", "default_config_toml", "read_config", "apply_config_defaults"]


class ConfigError(ValueError):
    """A configuration file that cannot be used (the message names the file and the key)."""


@dataclass(frozen=True)
class Key:
    section: str
    name: str
    dest: str  # the command-line option's destination
    kind: type
    default: object
    help: str


def _defaults():
    """The built-in defaults, read from the classes that own them (never written twice)."""
    from .inference import ModelPriors, SamplerSettings
    from .pipeline import RunOptions

    p, smp, run = ModelPriors(), SamplerSettings(), RunOptions()
    return {"height_m": p.camera_height.median, "height_log_sd": p.camera_height.log_sd, "stature": p.stature.mean,
            "stature_sd": p.stature.sd, "walkers": smp.n_walkers, "max_steps": smp.max_steps, "draws": smp.n_draws,
            "draws_per_noise_copy": smp.draws_per_noise_copy,
            "seed": smp.seed, "moves": smp.moves, "camera_side": run.camera_side, "branch": run.branch,
            "min_score": run.min_score, "lens": run.lens,
            "lens_k1_sd": run.lens_prior.sd, "height_allowance": run.height_allowance, "shot": run.shot,
            "slow_motion": run.slow_motion}


_D = _defaults()

#: Every key of the file, with the command-line option it stands for.
CONFIG_KEYS = (
    Key("priors", "camera_height_m", "height_m", float, _D["height_m"],
        "median of the camera-height prior (m): log-normal, 2-40 m at the default log-sd"),
    Key("priors", "camera_height_log_sd", "height_log_sd", float, _D["height_log_sd"],
        "log-sd of the camera-height prior (a small value such as 0.05 when the height is known)"),
    Key("priors", "stature_m", "stature", float, _D["stature"], "mean of the athlete's stature prior (m)"),
    Key("priors", "stature_sd", "stature_sd", float, _D["stature_sd"],
        "sd of the stature prior (m): 0.16 holds adults of 1.50-2.10 m; 0.02 when the stature is known"),
    Key("priors", "camera_height_allowance", "height_allowance", float, _D["height_allowance"],
        "systematic allowance on the camera height (sd of log height) for the track's lane-width and "
        "slope tolerances; 0 takes the lane geometry as exact"),
    Key("sampler", "walkers", "walkers", int, _D["walkers"], "emcee walkers"),
    Key("sampler", "max_steps", "max_steps", int, _D["max_steps"], "sampling budget (steps after burn-in)"),
    Key("sampler", "draws", "draws", int, _D["draws"], "posterior draws propagated to angles (the bands)"),
    Key("sampler", "draws_per_noise_copy", "draws_per_noise_copy", int, _D["draws_per_noise_copy"],
        "draws that share one re-noised copy of the keypoints in the bootstrap (1: a copy per draw)"),
    Key("sampler", "seed", "seed", int, _D["seed"], "random seed (results are reproducible for a seed)"),
    Key("sampler", "moves", "moves", str, _D["moves"],
        "emcee moves: 'de' (differential evolution, mixes faster on the correlated posterior) or 'stretch'"),
    Key("lens", "mode", "lens", str, _D["lens"],
        "without a known lens (dist): 'infer' k1 from the lane lines, or 'none' (no distortion)"),
    Key("lens", "k1_prior_sd", "lens_k1_sd", float, _D["lens_k1_sd"], "sd of the k1 prior (normal, mean 0)"),
    Key("lens", "dist", "dist", list, [],
        "known lens distortion [k1, k2, p1, p2, k3] (OpenCV order); [] = none assumed"),
    Key("camera", "side", "camera_side", str, _D["camera_side"],
        "'auto' (decided by the athlete's motion), 'main' (home-straight stands) or 'far' (across the infield)"),
    Key("camera", "shot", "shot", str, _D["shot"],
        "with camera cuts in a clip: the shot estimated: 'longest', 'all' (one camera: unreliable) or its number"),
    Key("camera", "slow_motion", "slow_motion", float, _D["slow_motion"],
        "a slow-motion replay's slow-down (4: recorded at 4x the rate it plays at); 1 = real time"),
    Key("camera", "branch", "branch", str, _D["branch"],
        "family branch: 'auto' (decided by evidence), 'narrow' (long lens far away) or 'wide' (close, steep)"),
    Key("detection", "model", "model", str, "", "ONNX pose model for videos (YOLO-pose or top-down); '' = none"),
    Key("detection", "det_model", "det_model", str, "", "ONNX person detector for a top-down model; '' = none"),
    Key("detection", "min_score", "min_score", float, _D["min_score"], "keypoints below this confidence are missing"),
)


def _toml_value(v):
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return repr(v)


def default_config_toml():
    """The commented default configuration (TOML text).

    >>> text = default_config_toml()
    >>> tomllib.loads(text)["priors"]["stature_m"]
    1.8
    """
    lines = ["# probreg configuration. Flags given on the command line override these values;",
             "# use it with: probreg run VIDEO_OR_CLIP --out OUT --config probreg.toml", ""]
    section = None
    for k in CONFIG_KEYS:
        if k.section != section:
            if section is not None:
                lines.append("")
            lines.append(f"[{k.section}]")
            section = k.section
        lines.append(f"# {k.help}")
        lines.append(f"{k.name} = {_toml_value(k.default)}")
    return "\n".join(lines) + "\n"


def read_config(path):
    """The options of a configuration file as ``{option destination: value}`` (only keys present).

    Raises
    ------
    ConfigError
        For a missing or malformed file, an unknown section or key, or a value of the wrong type.
    """
    path = Path(path)
    try:
        doc = tomllib.loads(path.read_text(encoding="utf-8-sig"))  # utf-8-sig: an editor's byte-order mark is dropped
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read the configuration ({exc.strerror or exc})") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{path}: not valid TOML ({exc})") from None
    known = {(k.section, k.name): k for k in CONFIG_KEYS}
    sections = {k.section for k in CONFIG_KEYS}
    out = {}
    for section, table in doc.items():
        if section not in sections or not isinstance(table, dict):
            raise ConfigError(f"{path}: unknown section [{section}] (known: {', '.join(sorted(sections))})")
        for name, value in table.items():
            key = known.get((section, name))
            if key is None:
                names = ", ".join(k.name for k in CONFIG_KEYS if k.section == section)
                raise ConfigError(f"{path}: unknown key '{name}' in [{section}] (known: {names})")
            out[key.dest] = _convert(path, key, value)
    return out


def _convert(path, key, value):
    where = f"{path}: [{key.section}] {key.name}"
    if key.kind is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{where} must be a number, got {value!r}")
        if key.dest == "height_allowance" and not 0 <= value < float("inf"):
            raise ConfigError(f"{where} must be a finite number >= 0, got {value!r}")
        if key.dest == "slow_motion" and not 0 < value < float("inf"):
            raise ConfigError(f"{where} must be a positive factor (4: a quarter of real speed), got {value!r}")
        if key.dest == "min_score" and not 0 <= value <= 1:
            raise ConfigError(f"{where} must be a confidence between 0 and 1, got {value!r}")
        return float(value)
    if key.kind is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{where} must be an integer, got {value!r}")
        if key.dest == "seed" and value < 0:
            raise ConfigError(f"{where} must be a whole number >= 0, got {value!r}")
        return value
    if key.kind is str:
        if not isinstance(value, str):
            raise ConfigError(f"{where} must be a string, got {value!r}")
        if key.dest == "camera_side" and value not in ("auto", "main", "far"):
            raise ConfigError(f"{where} must be 'auto', 'main' or 'far', got {value!r}")
        from .lanes.shots import is_shot_option

        if key.dest == "shot" and not is_shot_option(value):
            raise ConfigError(f"{where} must be 'longest', 'all' or a shot's number, got {value!r}")
        if key.dest == "lens" and value not in ("infer", "none"):
            raise ConfigError(f"{where} must be 'infer' or 'none', got {value!r}")
        return value or None  # '' = not given
    if key.dest == "dist":
        if not isinstance(value, list) or (value and (len(value) != 5 or not all(
                isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value))):
            raise ConfigError(f"{where} must be [] or five numbers [k1, k2, p1, p2, k3], all finite, got {value!r}")
        return ",".join(repr(float(v)) for v in value) if value else None
    raise ConfigError(f"{where}: unsupported value {value!r}")  # pragma: no cover


def apply_config_defaults(parser, path):
    """Defaults from the configuration file ``path`` for the sub-commands of ``parser`` that take
    ``--config`` (flags on the command line still override them).  Raises ``ValueError`` for a bad
    file."""
    values = read_config(path)
    for action in parser._subparsers._group_actions:
        for sp in action.choices.values():
            dests = {a.dest for a in sp._actions}
            if "config" in dests:
                sp.set_defaults(**{k: v for k, v in values.items() if k in dests})
