"""Vehicle configurations: loading the TOML files of docs/architecture.md, and the public names.

A configuration holds what is known about a vehicle before a flight: its mass and
rotor geometry (taken as known), the nominal (prior) physical parameters
θ = [c_T, c_D, c_M, j_x, j_y, j_z], its limits, its motors, its noise, and the model
effects beyond the paper's model that are known to act on it (``[effects.NAME]`` tables,
`mavsysid.vehicle.model_effects`).

This module is the entry point to configurations: `load_vehicle` here, the data types
(`mavsysid.vehicle.config_types`) and the writer (`mavsysid.vehicle.config_toml`)
re-exported. Validation is `mavsysid.vehicle.config_schema` (key by key) and
`mavsysid.vehicle.config_checks` (the assembled vehicle).
"""

from __future__ import annotations

import difflib
import tomllib
from pathlib import Path
from typing import Any

from mavsysid.vehicle.config_checks import check_vehicle
from mavsysid.vehicle.config_schema import validate_document
from mavsysid.vehicle.config_toml import save_vehicle, vehicle_to_toml
from mavsysid.vehicle.config_types import (
    PARAMETER_NAMES,
    PARAMETER_UNITS,
    Limits,
    MotorConfig,
    NoiseConfig,
    Parameters,
    RotorConfig,
    VehicleConfig,
    default_noise_densities,
)
from mavsysid.vehicle.constants import GRAVITY
from mavsysid.vehicle.model_effects import effect_from_values

from mavsysid.errors import ConfigError

__all__ = [
    "GRAVITY",
    "PARAMETER_NAMES",
    "PARAMETER_UNITS",
    "SHIPPED_VEHICLES",
    "Limits",
    "MotorConfig",
    "NoiseConfig",
    "Parameters",
    "RotorConfig",
    "VehicleConfig",
    "default_noise_densities",
    "load_vehicle",
    "save_vehicle",
    "vehicle_from_toml",
    "vehicle_to_toml",
]

#: Configurations shipped with the package, selectable by name.
SHIPPED_VEHICLES: tuple[str, ...] = ("firefly", "quad_x", "micro_quad", "sitl_quad")

_CONFIG_DIR = Path(__file__).with_name("configs")


def _resolve(spec: str | Path) -> tuple[Path, str, str]:
    """The file, the source label and the default name for a `load_vehicle` spec."""
    # Only a str can name a shipped vehicle: a Path is always meant as a file.
    if isinstance(spec, str) and spec in SHIPPED_VEHICLES:
        return _CONFIG_DIR / f"{spec}.toml", f"builtin:{spec}", spec
    path = Path(spec)
    if path.is_file():
        return path, str(spec), path.stem
    shipped = ", ".join(SHIPPED_VEHICLES)
    close = difflib.get_close_matches(str(spec), SHIPPED_VEHICLES, n=1, cutoff=0.6)
    hint = f"; did you mean {close[0]}?" if close else ""
    found = "a directory" if path.is_dir() else "no such file"
    raise ConfigError(
        f"{spec}: vehicle: a shipped vehicle name ({shipped}) or the path of a TOML file, "
        f"got {found}{hint}"
    )


def _read_toml(path: Path, label: str) -> dict[str, Any]:
    """Parse a TOML file, turning every failure into a one-line ConfigError."""
    try:
        text = path.read_bytes().decode("utf-8")
    except OSError as exc:
        raise ConfigError(f"{label}: file: a readable file, got {exc.strerror}") from None
    except UnicodeDecodeError as exc:
        raise ConfigError(
            f"{label}: file: UTF-8 text, got an invalid byte at offset {exc.start}"
        ) from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        detail = " ".join(str(exc).split())
        raise ConfigError(f"{label}: TOML syntax: valid TOML, got {detail}") from None


def _build(values: dict[str, Any], name: str, source: str) -> VehicleConfig:
    """Assemble a VehicleConfig from the output of `validate_document`."""
    rotors = tuple(
        RotorConfig(position=(p[0], p[1], p[2]), direction=d) for p, d in values["rotors"]
    )
    noise = dict(values["noise"])
    force, moment = default_noise_densities(values["mass"], tuple(values["parameters"]["J"]))
    noise.setdefault("force_density", force)
    noise.setdefault("moment_density", moment)
    limits = dict(values["limits"])
    allocation = limits.pop("allocation", VehicleConfig.allocation)
    return VehicleConfig(
        name=name,
        mass=values["mass"],
        rotors=rotors,
        parameters=Parameters(**values["parameters"]),
        limits=Limits(**limits),
        motor=MotorConfig(**values["motor"]),
        noise=NoiseConfig(**noise),
        source=source,
        effects=tuple(effect_from_values(n, v) for n, v in values["effects"]),
        autopilot_frame=values["autopilot_frame"],
        box=values["box"],
        allocation=allocation,
        imu_position=values["imu_position"],
    )


def load_vehicle(spec: str | Path) -> VehicleConfig:
    """Load a vehicle configuration by shipped name or by TOML path.

    Parameters
    ----------
    spec : str or Path
        A shipped name (see `SHIPPED_VEHICLES`; a str only) or the path of a TOML file.
        A shipped vehicle gets ``name = spec`` and ``source = "builtin:NAME"``; a file
        gets the name of its top-level ``name`` key (else the file stem) and
        ``source = str(spec)``.

    Returns
    -------
    VehicleConfig
        Optional keys absent from the file take the dataclass defaults, except the
        noise densities (see `default_noise_densities`), which scale with the vehicle.

    Raises
    ------
    ConfigError
        The file is missing or does not satisfy the schema; the one-line message names
        the file, the key and what was expected.
    """
    path, source, default_name = _resolve(spec)
    values = validate_document(source, _read_toml(path, source))
    builtin = source.startswith("builtin:")
    name = default_name if builtin or values["name"] is None else values["name"]
    config = _build(values, name, source)
    check_vehicle(source, config)
    return config


def vehicle_from_toml(text: str, label: str) -> VehicleConfig:
    """A vehicle configuration from TOML text, as a flight's ``meta.json`` or a trajectory
    file records it (`vehicle_to_toml`).

    Parameters
    ----------
    text : str
        The configuration as TOML.
    label : str
        Where the text comes from, as error messages name it.

    Raises
    ------
    ConfigError
        Not TOML, or a document that does not satisfy the schema; one line.
    """
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        detail = " ".join(str(exc).split())
        raise ConfigError(f"{label}: TOML syntax: valid TOML, got {detail}") from None
    values = validate_document(label, doc)
    return _build(values, values["name"] or label, label)
