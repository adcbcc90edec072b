"""From balance coefficients to θ, and the parts of its honest σ.

**θ from the coefficients** (`theta_from_coefficients`): c_T and c_T c_D from the force
rows; j_x = c_T / (c_T/j_x), j_y likewise; j_z from the gyroscopic coefficients of roll and
pitch (j_z = j_y − g_x j_x and j_z = j_x + g_y j_y, paper Eq. euler solved for j_z,
combined by inverse variance); c_M = (c_M/j_z) j_z; each nuisance quantity from its force
and torque coefficients, combined by inverse variance. The covariance follows by the delta
method (a numerical Jacobian). The force and torque fits are independent (`stack`).

**The sensors' priors** (`with_nuisance_prior`): a nuisance quantity the vehicle file gives
a prior σ (an accelerometer's bias, 0.1 m/s² for a calibrated one) is not a free intercept.
Left free, a bias along the thrust trades with c_T one for one (0.1 m/s² is 1 % of c_T at
hover), and c_T then rests on the thrust's variations alone, which lagging or slowly
sampled rotor speeds attenuate (ArduCopter SITL's DataFlash log, motor outputs at 10 Hz:
c_T −5.0 % with the bias at +0.50 m/s²). The data's estimate is combined with the prior
on those quantities as two independent Gaussian measurements; θ follows through its
covariance with them.

**σ** has six parts, added in quadrature (`widened_sigma`, `SIGMA_PARTS`): the Newey–West
sandwich; errors in the variables (the interval reaches the reverse regression's value,
σ_eiv = |θ_forward − θ_reverse| / 1.96); the two halves of the flight and the two halves of
the band, each fitted alone (a disagreement beyond their own σ is model error the sandwich
cannot see and adds (d² − σ_a² − σ_b²)/4, `split_widening`); the two routes to j_z, which
carry over to c_M; and the thrust row's second-order bias.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from mavsysid.estimation.balance.rows import (
    FORCE_COEFFICIENTS,
    STACKED_COEFFICIENTS,
    TORQUE_COEFFICIENTS,
)
from mavsysid.estimation.results import COMBINATION_NAMES, Z95, DataTheta
from mavsysid.vehicle.parameters import C_M, PARAMETER_NAMES

__all__ = ["J_Z", "coefficients_from_theta", "errors_in_variables_sigma", "split_widening", "stack",
           "stacked_covariance", "theta_from_coefficients", "unstack", "widened_sigma",
           "with_nuisance_prior"]


#: Where j_z sits in θ.
J_Z = PARAMETER_NAMES.index("j_z")

# Indices into the stacked coefficient vector (`STACKED_COEFFICIENTS`).
_CT, _CTCD, _AX, _GX, _AY, _GY, _BZ, _DZ, _GZ, _RZ = (
    STACKED_COEFFICIENTS.index(name) for name in (
        "c_T", "c_T*c_D", "c_T/j_x", "g_x", "c_T/j_y", "g_y", "c_M/j_z", "drag_z", "g_z",
        "rotor_inertia_z"))
_COUNT = len(STACKED_COEFFICIENTS)


def _j_z_routes(b: np.ndarray) -> np.ndarray:
    c_t = b[_CT]
    with np.errstate(divide="ignore", invalid="ignore"):
        j_x, j_y = c_t / b[_AX], c_t / b[_AY]
        return np.array([j_y - b[_GX] * j_x, j_x + b[_GY] * j_y])


def _jacobian(f: Callable[[np.ndarray], np.ndarray], b: np.ndarray) -> np.ndarray:
    f0 = f(b)
    jac = np.zeros((f0.size, b.size))
    for k in range(b.size):
        step = 1e-6 * (abs(b[k]) if b[k] != 0.0 else 1.0)
        shifted = b.copy()
        shifted[k] += step
        jac[:, k] = (f(shifted) - f0) / step
    return jac


def stack(force: np.ndarray, torque: np.ndarray) -> np.ndarray:
    """The stacked coefficient vector of a force and a torque fit, shape (13 + 2E,).

    `STACKED_COEFFICIENTS` (the model's force, then torque coefficients) first, then the
    E nuisance quantities' force coefficients and their torque coefficients.

    Parameters
    ----------
    force : ndarray, shape (3 + E,)
        The force fit's coefficients (`FORCE_COEFFICIENTS`, then the nuisance quantities).
    torque : ndarray, shape (10 + E,)
        The torque fit's (`TORQUE_COEFFICIENTS`, then the nuisance quantities).
    """
    f, m = len(FORCE_COEFFICIENTS), len(TORQUE_COEFFICIENTS)
    return np.concatenate([force[:f], torque[:m], force[f:], torque[m:]])


def stacked_covariance(force: np.ndarray, torque: np.ndarray) -> np.ndarray:
    """The covariance of `stack` of two independent fits, from theirs.

    Parameters
    ----------
    force : ndarray, shape (3 + E, 3 + E)
        The force fit's covariance.
    torque : ndarray, shape (10 + E, 10 + E)
        The torque fit's.
    """
    f, m = len(FORCE_COEFFICIENTS), len(TORQUE_COEFFICIENTS)
    order = np.r_[np.arange(f), force.shape[0] + np.arange(m), np.arange(f, force.shape[0]),
                  force.shape[0] + np.arange(m, torque.shape[0])]
    joint = np.zeros((order.size, order.size))
    joint[:force.shape[0], :force.shape[0]] = force
    joint[force.shape[0]:, force.shape[0]:] = torque
    return joint[np.ix_(order, order)]


def unstack(coefficients: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The force and the torque fit's coefficients of a `stack` vector.

    Parameters
    ----------
    coefficients : ndarray, shape (13 + 2E,)
        As `stack` returns.
    """
    f, m = len(FORCE_COEFFICIENTS), len(TORQUE_COEFFICIENTS)
    e = (coefficients.size - f - m) // 2
    b = np.asarray(coefficients, float)
    return (np.concatenate([b[:f], b[f + m:f + m + e]]),
            np.concatenate([b[f:f + m], b[f + m + e:]]))


def _extras(x: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """Each nuisance quantity from its force and torque coefficients, combined."""
    e = (x.size - _COUNT) // 2
    return weight[:, 0] * x[_COUNT:_COUNT + e] + weight[:, 1] * x[_COUNT + e:]


def _extra_weights(b: np.ndarray, cov: np.ndarray, unexcited: np.ndarray) -> np.ndarray:
    """Inverse-variance weights (E, 2) of each nuisance quantity's force and torque value."""
    e = (b.size - _COUNT) // 2
    var = np.diag(cov)[_COUNT:].reshape(2, e).T
    use = ~unexcited[_COUNT:].reshape(2, e).T & (var > 0.0)
    w = np.where(use, 1.0 / np.where(use, var, 1.0), 0.0)
    total = w.sum(axis=1, keepdims=True)
    return np.where(total > 0.0, w / np.where(total > 0.0, total, 1.0), 0.5)


def theta_from_coefficients(coefficients: np.ndarray, covariance: np.ndarray) -> DataTheta:
    """θ and the combinations from the stacked coefficients (module docstring).

    Parameters
    ----------
    coefficients : ndarray, shape (13 + 2E,)
        `stack` of the force and torque coefficients.
    covariance : ndarray, shape (13 + 2E, 13 + 2E)
        Their covariance (inf on the diagonal of a coefficient not excited).

    Returns
    -------
    DataTheta
        θ, then the E nuisance quantities (each its force and torque values combined by
        inverse variance).
    """
    b = np.asarray(coefficients, float)
    cov = np.where(np.isfinite(covariance), covariance, 0.0)
    unexcited = ~np.isfinite(np.diag(covariance))
    routes_cov = _jacobian(_j_z_routes, b)
    routes_cov = routes_cov @ cov @ routes_cov.T
    route_var = np.diag(routes_cov).copy()
    route_var[[unexcited[[_GX, _AX]].any(), unexcited[[_GY, _AY]].any()]] = np.inf
    weight = np.where(np.isfinite(route_var) & (route_var > 0), 1.0 / route_var, 0.0)
    weight = weight / weight.sum() if weight.sum() > 0 else np.array([0.5, 0.5])
    extra_weight = _extra_weights(b, cov, unexcited)

    def theta(x: np.ndarray) -> np.ndarray:
        c_t = x[_CT]
        j_z = float(weight @ _j_z_routes(x))
        return np.concatenate([[c_t, x[_CTCD] / c_t, x[_BZ] * j_z, c_t / x[_AX],
                                c_t / x[_AY], j_z], _extras(x, extra_weight),
                               [x[_BZ], -x[_RZ]]])

    # A coefficient near 0 makes the quotients infinite: their σ is then not a number,
    # which the determination rule reads as undetermined.
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        full = theta(b)
        jac = _jacobian(theta, b)
        full_cov = jac @ cov @ jac.T
    # A coefficient the flight does not excite makes everything that uses it unknown.
    unknown = (np.abs(jac[:, unexcited]) > 0).any(axis=1) if unexcited.any() else \
        np.zeros(full.size, bool)
    var = np.where(unknown, np.inf, np.diag(full_cov))
    full_cov[np.diag_indices_from(full_cov)] = var
    p = full.size - len(COMBINATION_NAMES)
    with np.errstate(divide="ignore", invalid="ignore"):
        routes = _j_z_routes(b)
        spread = split_widening(routes[0], np.sqrt(route_var[0]), routes[1],
                                np.sqrt(route_var[1]))
        route_sigma = np.zeros(p)
        route_sigma[J_Z] = spread
        route_sigma[C_M] = abs(full[p]) * spread
    return DataTheta(full[:p], full_cov[:p, :p], full[p:], np.sqrt(np.abs(var[p:])),
                     route_sigma)


def with_nuisance_prior(theta: DataTheta, prior_value: np.ndarray, prior_sigma: np.ndarray
                        ) -> DataTheta:
    """``theta`` combined with the prior of its nuisance quantities (module docstring).

    With N the nuisance quantities the data excite and whose prior σ is finite and
    positive, K = Σ[:, N] (Σ[N, N] + P)⁻¹: value + K (prior − value[N]), Σ − K Σ[N, :].
    θ keeps no prior of its own (its prior is the vehicle file's guess, not a measurement).

    Parameters
    ----------
    theta : DataTheta
        The data's θ and nuisance quantities (6 + E), with their covariance.
    prior_value, prior_sigma : ndarray, shape (6 + E,)
        The prior, SI; only entries beyond θ are used.

    Returns
    -------
    DataTheta
        The combination; ``theta`` itself when there is nothing to combine.
    """
    value, cov = theta.value, theta.covariance
    six = len(PARAMETER_NAMES)
    sigma = np.asarray(prior_sigma, float)
    var = np.diag(cov)
    use = np.zeros(value.size, bool)
    use[six:] = (np.isfinite(sigma[six:]) & (sigma[six:] > 0.0) & np.isfinite(var[six:])
                 & np.isfinite(value[six:]))
    n = np.flatnonzero(use)
    if not n.size:
        return theta
    finite = np.where(np.isfinite(cov), cov, 0.0)
    gain = finite[:, n] @ np.linalg.inv(finite[np.ix_(n, n)] + np.diag(sigma[n] ** 2))
    new_value = value + gain @ (np.asarray(prior_value, float)[n] - value[n])
    new_cov = cov - gain @ finite[n, :]
    return DataTheta(new_value, 0.5 * (new_cov + new_cov.T), theta.combinations,
                     theta.combination_sigma, theta.route_sigma)


def coefficients_from_theta(theta: np.ndarray, nuisance: np.ndarray | None = None
                            ) -> np.ndarray:
    """The stacked coefficients a θ implies, shape (13 + 2E,): the inverse of the mapping
    above.

    Parameters
    ----------
    theta : ndarray, shape (6 + E,)
        θ, then the E nuisance quantities (each its force and its torque coefficient), SI.
    nuisance : ndarray, shape (13 + 2E,), optional
        Coefficients beyond the paper's model (the rotors' gyroscopic and reaction terms)
        are taken from here; 0 without it.
    """
    theta = np.asarray(theta, float)
    extras = theta[len(PARAMETER_NAMES):]
    c_t, c_d, c_m, j_x, j_y, j_z = theta[:len(PARAMETER_NAMES)]
    out = (np.zeros(_COUNT + 2 * extras.size) if nuisance is None
           else np.array(nuisance, float))
    out[[_CT, _CTCD, _AX, _GX, _AY, _GY, _BZ, _DZ, _GZ]] = [
        c_t, c_t * c_d, c_t / j_x, -(j_z - j_y) / j_x, c_t / j_y, -(j_x - j_z) / j_y, c_m / j_z,
        c_t * c_d / j_z, -(j_y - j_x) / j_z]
    out[_COUNT:] = np.concatenate([extras, extras])
    return out


def split_widening(a: np.ndarray, sigma_a: np.ndarray, b: np.ndarray, sigma_b: np.ndarray
                   ) -> np.ndarray:
    """σ added by two independent estimates that disagree beyond their σ, shape like ``a``.

    sqrt(max(0, (a − b)² − σ_a² − σ_b²) / 4); 0 where either is not finite.
    """
    with np.errstate(invalid="ignore"):
        excess = (np.asarray(a) - b) ** 2 - np.asarray(sigma_a) ** 2 - np.asarray(sigma_b) ** 2
        out = np.sqrt(np.maximum(excess, 0.0) / 4.0)
    return np.where(np.isfinite(out), out, 0.0)


def widened_sigma(parts: np.ndarray) -> np.ndarray:
    """The quadrature sum of σ parts, shape (P,) from (len(SIGMA_PARTS), P)."""
    with np.errstate(over="ignore"):  # a part beyond float range is an infinite σ
        return np.sqrt(np.sum(np.asarray(parts, float) ** 2, axis=0))


def errors_in_variables_sigma(forward: np.ndarray, reverse: np.ndarray) -> np.ndarray:
    """|forward − reverse| / 1.96 (0 where the reverse value is not formed)."""
    with np.errstate(invalid="ignore"):
        out = np.abs(np.asarray(forward) - reverse) / Z95
    return np.where(np.isfinite(out), out, 0.0)


