"""Vehicle configurations: the TOML schema of docs/architecture.md as frozen dataclasses.

A configuration holds what is known about a vehicle before a flight: its mass and
rotor geometry (taken as known), the nominal (prior) physical parameters
θ = [c_T, c_D, c_M, j_x, j_y, j_z], its limits, its motors, its noise, and the model
effects beyond the paper's model that are known to act on it (``[effects.NAME]`` tables,
`mavsysid.vehicle.model_effects`).
"""

from __future__ import annotations

import difflib
import math
import tomllib
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np
from mavsysid.vehicle.config_schema import check_vehicle, validate_document
from mavsysid.vehicle.constants import GRAVITY
from mavsysid.vehicle.model_effects import ModelEffect, effect_from_values

from mavsysid.errors import ConfigError

__all__ = [
    "GRAVITY",
    "PARAMETER_NAMES",
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
    "vehicle_to_toml",
]


#: Order of the parameter vector θ everywhere in mavsysid.
PARAMETER_NAMES: tuple[str, ...] = ("c_T", "c_D", "c_M", "j_x", "j_y", "j_z")

#: Configurations shipped with the package, selectable by name.
SHIPPED_VEHICLES: tuple[str, ...] = ("firefly", "quad_x", "micro_quad")

_CONFIG_DIR = Path(__file__).with_name("configs")

#: Default unmodelled linear acceleration noise density, m/s²·√s.
LINEAR_NOISE_DENSITY = 0.02
#: Default unmodelled angular acceleration noise density, rad/s²·√s.
ANGULAR_NOISE_DENSITY = 0.02


@dataclass(frozen=True)
class RotorConfig:
    """One rotor.

    Attributes
    ----------
    position : tuple of 3 float
        Rotor hub position relative to the centre of gravity, m, body FLU frame.
    direction : int
        +1 spins counter-clockwise seen from above (reaction torque -c_M n² about
        z_B), -1 clockwise. The paper's ε_i.
    """

    position: tuple[float, float, float]
    direction: int


@dataclass(frozen=True)
class Parameters:
    """The identified parameters θ, in SI units.

    Attributes
    ----------
    c_T : float
        Thrust coefficient, N/(rad/s)²: rotor thrust c_T n².
    c_D : float
        Rotor drag coefficient, s/m: rotor drag -c_T n² diag(c_D, c_D, 0)(v_B + ω × r_i).
    c_M : float
        Moment coefficient, N·m/(rad/s)² (absolute, not RotorS's ratio c_M/c_T).
    J : tuple of 3 float
        Principal moments of inertia [j_x, j_y, j_z], kg·m².
    """

    c_T: float
    c_D: float
    c_M: float
    J: tuple[float, float, float]

    def as_array(self) -> np.ndarray:
        """θ as a float array of shape (6,), in the order of `PARAMETER_NAMES`."""
        return np.array([self.c_T, self.c_D, self.c_M, *self.J], dtype=float)

    @classmethod
    def from_array(cls, theta: np.ndarray) -> Parameters:
        """Build from θ of shape (6,) in the order of `PARAMETER_NAMES`."""
        t = [float(v) for v in np.asarray(theta, dtype=float).reshape(6)]
        return cls(c_T=t[0], c_D=t[1], c_M=t[2], J=(t[3], t[4], t[5]))


@dataclass(frozen=True)
class Limits:
    """Actuator and planner limits (optional `[limits]` keys have these defaults)."""

    rotor_speed_max: float
    rotor_speed_min: float = 0.0
    thrust_min_ratio: float = 0.5
    thrust_max_ratio: float = 1.8
    body_rate_max: float = 3.0
    yaw_acceleration_max: float = 2.0 * math.pi
    speed_max: float = 3.0
    segment_time_max: float = 3.0


@dataclass(frozen=True)
class MotorConfig:
    """Motor lag (simulator truth side) and the motor curve (logs without rotor speeds).

    Attributes
    ----------
    time_constant : float
        First-order lag between commanded and actual rotor speed, s.
    pwm_min, pwm_max : float
        Motor output PWM for zero and full throttle u, µs.
    thrust_expo : float
        ArduPilot's MOT_THST_EXPO e in [0, 1]: thrust ∝ (1 − e) u + e u², so a rotor
        speed is rotor_speed_max · sqrt((1 − e) u + e u²).
    """

    time_constant: float = 0.02
    pwm_min: float = 1000.0
    pwm_max: float = 2000.0
    thrust_expo: float = 0.65


@dataclass(frozen=True)
class NoiseConfig:
    """Sensor noise (σ) and process-noise densities.

    Attributes
    ----------
    position_sigma : float
        Motion-capture position noise σ, m.
    attitude_sigma : float
        Motion-capture attitude noise σ, rad (per axis of the body-frame error).
    rotor_speed_sigma : float
        Noise σ on logged rotor speeds, rad/s.
    force_density : float
        White-noise density of the unmodelled body force, N·√s (continuous time).
    moment_density : float
        White-noise density of the unmodelled body moment, N·m·√s.
    """

    position_sigma: float = 0.0005
    attitude_sigma: float = math.radians(0.1)
    rotor_speed_sigma: float = 0.0
    force_density: float = 0.0
    moment_density: float = 0.0


@dataclass(frozen=True)
class VehicleConfig:
    """A complete vehicle description.

    Attributes
    ----------
    name : str
        Short name (the shipped name, or the file stem).
    mass : float
        Mass, kg (weighed, not estimated).
    rotors : tuple of RotorConfig
        The rotors, in the order of the rotor-speed columns n1..nk of a log.
    parameters : Parameters
        Nominal (prior) values of θ.
    limits, motor, noise
        See the respective classes.
    effects : tuple of ModelEffect
        Known model effects (``[effects.NAME]``), part of the model everywhere: the
        simulators' physics and the estimator's model. Empty by default.
    source : str
        Where the configuration came from (a path, or ``builtin:NAME``).
    """

    name: str
    mass: float
    rotors: tuple[RotorConfig, ...]
    parameters: Parameters
    limits: Limits
    motor: MotorConfig = field(default_factory=MotorConfig)
    noise: NoiseConfig = field(default_factory=NoiseConfig)
    source: str = ""
    effects: tuple[ModelEffect, ...] = ()

    @property
    def rotor_count(self) -> int:
        """Number of rotors k."""
        return len(self.rotors)

    @property
    def rotor_positions(self) -> np.ndarray:
        """Rotor positions, shape (k, 3), m, body FLU."""
        return np.array([r.position for r in self.rotors], dtype=float)

    @property
    def rotor_directions(self) -> np.ndarray:
        """Rotor spin directions ε_i, shape (k,), float ±1."""
        return np.array([r.direction for r in self.rotors], dtype=float)

    @property
    def theta(self) -> np.ndarray:
        """Nominal θ, shape (6,)."""
        return self.parameters.as_array()

    @property
    def hover_thrust(self) -> float:
        """Collective thrust in hover m g, N."""
        return self.mass * GRAVITY

    def with_parameters(self, parameters: Parameters | np.ndarray) -> VehicleConfig:
        """A copy with other nominal parameters (a `Parameters` or θ of shape (6,))."""
        if not isinstance(parameters, Parameters):
            parameters = Parameters.from_array(parameters)
        return replace(self, parameters=parameters)


def default_noise_densities(
    mass: float, inertia: tuple[float, float, float]
) -> tuple[float, float]:
    """Process-noise densities used when `[noise]` does not give them.

    Stated as unmodelled accelerations so that one default suits a 30 g quad and a 3 kg
    hexacopter alike: 0.02 m/s²·√s of linear and 0.02 rad/s²·√s of angular acceleration
    noise. Estimation can fit the level to a flight (`mavsysid.estimation.noise_fit`).

    Parameters
    ----------
    mass : float
        Vehicle mass, kg.
    inertia : tuple of 3 float
        Principal moments of inertia, kg·m².

    Returns
    -------
    force_density : float
        ``0.02 m``, N·√s.
    moment_density : float
        ``0.02 mean(J)``, N·m·√s.
    """
    return LINEAR_NOISE_DENSITY * mass, ANGULAR_NOISE_DENSITY * float(np.mean(inertia))


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
    return VehicleConfig(
        name=name,
        mass=values["mass"],
        rotors=rotors,
        parameters=Parameters(**values["parameters"]),
        limits=Limits(**values["limits"]),
        motor=MotorConfig(**values["motor"]),
        noise=NoiseConfig(**noise),
        source=source,
        effects=tuple(effect_from_values(n, v) for n, v in values["effects"]),
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


def _toml_string(text: str) -> str:
    """A TOML basic string."""
    escapes = {'"': '\\"', "\\": "\\\\", "\n": "\\n", "\t": "\\t", "\r": "\\r"}
    out = []
    for ch in text:
        if ch in escapes:
            out.append(escapes[ch])
        elif ord(ch) < 0x20 or ord(ch) == 0x7F:
            out.append(f"\\u{ord(ch):04X}")
        else:
            out.append(ch)
    return '"' + "".join(out) + '"'


def _toml_float(value: float) -> str:
    """A float that reads back bit for bit (repr is the shortest exact form)."""
    # float() first: numpy 2 scalars repr as "np.float64(…)", which is not TOML.
    return repr(float(value))


def _toml_value(value: float | tuple[float, ...]) -> str:
    """A float or a tuple of floats as TOML."""
    if isinstance(value, tuple):
        return "[" + ", ".join(_toml_float(v) for v in value) + "]"
    return _toml_float(value)


def vehicle_to_toml(config: VehicleConfig) -> str:
    """The full configuration as TOML text, defaults included.

    Parameters
    ----------
    config : VehicleConfig
        The configuration to write.

    Returns
    -------
    str
        A TOML document that `load_vehicle` reads back to a config equal to `config`
        except for `source`. Floats are written with `repr`, so they round-trip exactly.
    """
    lines = [
        "# Vehicle configuration written by mavsysid. Units: SI, angles in rad, rotor",
        "# speeds in rad/s, rotor positions in the body FLU frame relative to the CoG.",
    ]
    if config.source:
        # TOML comments may not hold control characters.
        lines.append("# Source: " + "".join(c for c in config.source if c.isprintable()))
    lines += ["", f"name = {_toml_string(config.name)}", f"mass = {_toml_float(config.mass)}"]
    for rotor in config.rotors:
        lines += ["", "[[rotors]]", f"position = {_toml_value(rotor.position)}",
                  f"direction = {int(rotor.direction):+d}"]
    # The tables are flat tables of floats (J a float triple): writing every field
    # keeps fields added to the dataclasses later saved without touching this function.
    for table, section in (("parameters", config.parameters), ("limits", config.limits),
                           ("motor", config.motor), ("noise", config.noise)):
        lines += ["", f"[{table}]"]
        lines += [f"{f.name} = {_toml_value(getattr(section, f.name))}" for f in fields(section)]
    for effect in config.effects:
        lines += ["", f"[effects.{effect.name}]"]
        lines += [f"{k} = {_toml_float(v)}" for k, v in effect.as_dict().items()]
    return "\n".join(lines) + "\n"


def save_vehicle(config: VehicleConfig, path: str | Path) -> None:
    """Write `config` as a TOML file (see `vehicle_to_toml`).

    Parameters
    ----------
    config : VehicleConfig
        The configuration to write.
    path : str or Path
        The destination file; it is overwritten.
    """
    Path(path).write_text(vehicle_to_toml(config), encoding="utf-8")
