"""Writing a vehicle configuration as TOML, which `mavsysid.vehicle.config.load_vehicle` reads."""

from __future__ import annotations

from dataclasses import fields
from pathlib import Path

from mavsysid.vehicle.config_types import VehicleConfig

__all__ = ["save_vehicle", "vehicle_to_toml"]


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
    if config.autopilot_frame is not None:
        lines += ["", "# The rotors are this autopilot frame's motor outputs.", "[autopilot]",
                  f"frame = {_toml_string(config.autopilot_frame)}"]
    if config.box is not None:
        lines += ["", "# Flight box, m, world ENU: x_min, y_min, z_min, x_max, y_max, z_max.",
                  "[flight]", f"box = {_toml_value(tuple(config.box))}"]
    if config.imu_position is not None:
        lines += ["", "# The IMU's offset from the centre of gravity, m, body FLU.", "[imu]",
                  f"position = {_toml_value(tuple(config.imu_position))}"]
    # The tables are flat tables of floats (J a float triple): writing every field
    # keeps fields added to the dataclasses later saved without touching this function.
    for table, section in (("parameters", config.parameters), ("limits", config.limits),
                           ("motor", config.motor), ("noise", config.noise)):
        lines += ["", f"[{table}]"]
        lines += [f"{f.name} = {_toml_value(getattr(section, f.name))}" for f in fields(section)]
        if table == "limits" and config.allocation != VehicleConfig.allocation:
            lines.append(f"allocation = {_toml_string(config.allocation)}")
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
