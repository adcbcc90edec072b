"""The batch refinement's multiple-shooting problem: residuals, Jacobian, normal equations.

See `mavsysid.estimation.batch` for the cost. `ShootingProblem` holds the flight in the
kernels' arrays and evaluates the residuals at given nodes and θ, with the Jacobian as a
sparse matrix (for `scipy.optimize.least_squares`) or directly as the blocks of JᵀJ and
Jᵀr (`mavsysid.estimation.block_solve.BlockSystem`, what the refinement solves).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from mavsysid.estimation.batch_kernels import (
    MODE_COO,
    MODE_NORMAL,
    MODE_RESIDUALS,
    inject_kernel,
    shoot_kernel,
)
from mavsysid.estimation.block_solve import BlockSystem
from mavsysid.estimation.flight_data import FlightData
from mavsysid.estimation.input_noise import step_process_noise
from mavsysid.estimation.results import ParameterEstimate
from mavsysid.vehicle.linearization import ErrorStateModel

__all__ = ["ShootingProblem", "apply_step", "node_indices", "whitening"]


def node_indices(t: np.ndarray, node_interval: float) -> np.ndarray:
    """Sample index of each shooting node, and the sample count last, shape (K+1,).

    ``node_interval`` s between nodes (rounded to whole median sample intervals); 0: a
    node at every sample but the last.
    """
    dt = float(np.median(np.diff(t)))
    step = max(1, round(node_interval / dt))
    return np.append(np.arange(0, len(t) - 1, step), len(t)).astype(np.int64)


def whitening(Q: np.ndarray) -> np.ndarray:
    """W with Wᵀ W = Q⁻¹ for each (12, 12) block of Q (M, 12, 12), robust to a singular Q."""
    tr = np.trace(Q, axis1=1, axis2=2)
    q = 0.5 * (Q + np.swapaxes(Q, 1, 2)) + np.eye(12) * (1e-12 + 1e-9 * tr / 12)[:, None, None]
    return np.linalg.inv(np.linalg.cholesky(q))


def apply_step(model: ErrorStateModel, nodes: np.ndarray, theta: np.ndarray,
               step_nodes: np.ndarray, step_theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Nodes ⊞ their steps (K, 12) and θ + scale × its step (6,), SI."""
    new_nodes = np.empty_like(nodes)
    for k in range(nodes.shape[0]):
        inject_kernel(nodes[k], step_nodes[k], new_nodes[k])
    return new_nodes, theta + model.theta_scale * step_theta


@dataclass
class ShootingProblem:
    """The shooting problem of one flight segment.

    Attributes
    ----------
    flight : FlightData
        In the model's terms.
    model : ErrorStateModel
    node_idx : ndarray, shape (K+1,)
        From `node_indices`.
    prior : ParameterEstimate
    sigma : tuple of 2 float
        Position σ (m) and attitude σ (rad) of the measurements.
    W : ndarray, shape (max(K-1, 1), 12, 12)
        Whitening of each defect (set from `interval_noise`).
    wrench : ndarray, shape (N, 6), optional
        Known effects' body force (N) and torque (N·m).
    """

    flight: FlightData
    model: ErrorStateModel
    node_idx: np.ndarray
    prior: ParameterEstimate
    sigma: tuple[float, float]
    W: np.ndarray
    wrench: np.ndarray | None = None
    arrays: dict[str, np.ndarray] = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        fl = self.flight
        t = np.ascontiguousarray(fl.t, dtype=float)
        n = np.ascontiguousarray(fl.rotor_speeds, dtype=float)
        _, r, eps, _ = self.model.kernel_args()
        self.arrays = {
            "t": t, "z": np.ascontiguousarray(np.hstack([fl.position, fl.quaternion])), "n": n,
            "w": (np.zeros((len(fl), 6)) if self.wrench is None
                  else np.ascontiguousarray(self.wrench, dtype=float)),
            # Each step's process noise, with the slow inputs' interpolation error.
            "Qc": step_process_noise(self.model.process_noise_density(), t, n, fl.inputs,
                                     self.prior.value, r, eps),
        }

    @property
    def node_count(self) -> int:
        """K."""
        return len(self.node_idx) - 1

    @property
    def residual_count(self) -> int:
        """Rows of the residual vector: 6 per sample, 12 per defect, 6 for the prior."""
        return 6 * len(self.flight) + 12 * (self.node_count - 1) + 6

    def _run(self, nodes: np.ndarray, theta: np.ndarray, mode: int, want_q: bool = False,
             coo: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
             system: BlockSystem | None = None) -> tuple[np.ndarray, np.ndarray]:
        a = self.arrays
        K = self.node_count
        res = np.empty(self.residual_count)
        rows, cols, vals = coo if coo is not None else (np.empty(1, np.int64),) * 2 + (
            np.empty(1),)
        system = system if system is not None else BlockSystem.zeros(1)
        Q_out = np.empty((max(K - 1, 1), 12, 12))
        mass, r, eps, scale = self.model.kernel_args()
        m, _ = shoot_kernel(nodes, theta, a["t"], a["z"], a["n"], a["w"], self.node_idx, mass, r,
                            eps, scale, a["Qc"], self.W, self.sigma[0], self.sigma[1], mode,
                            want_q, res, rows, cols, vals, Q_out, system.D, system.U, system.B,
                            system.T, system.g, system.gt)
        res[m:] = (theta - self.prior.value) / self.prior_sigma
        return res, Q_out

    @property
    def prior_sigma(self) -> np.ndarray:
        """σ of the θ prior, SI (6,)."""
        return np.sqrt(np.diag(self.prior.covariance))

    def interval_noise(self, nodes: np.ndarray, theta: np.ndarray) -> np.ndarray:
        """Process noise accumulated over each node interval, (max(K-1, 1), 12, 12)."""
        return self._run(nodes, theta, MODE_RESIDUALS, want_q=True)[1]

    def residuals(self, nodes: np.ndarray, theta: np.ndarray) -> np.ndarray:
        """The whitened residual vector r."""
        return self._run(nodes, theta, MODE_RESIDUALS)[0]

    def normal_equations(self, nodes: np.ndarray, theta: np.ndarray
                         ) -> tuple[np.ndarray, BlockSystem]:
        """r, and JᵀJ with Jᵀr in blocks (θ in its scaled units)."""
        system = BlockSystem.zeros(self.node_count)
        res, _ = self._run(nodes, theta, MODE_NORMAL, system=system)
        w = self.model.theta_scale / self.prior_sigma
        system.T[np.diag_indices(6)] += w * w
        system.gt[:] += w * res[-6:]
        return res, system

    def jacobian(self, nodes: np.ndarray, theta: np.ndarray) -> tuple[np.ndarray, sp.csr_matrix]:
        """r and J as a sparse matrix (columns: 12 per node, then the 6 scaled θ)."""
        K = self.node_count
        n_meas = len(self.flight)
        m = self.residual_count - 6
        nnz = 6 * 18 * n_meas + 12 * 30 * (K - 1)
        coo = (np.empty(nnz, np.int64), np.empty(nnz, np.int64), np.empty(nnz))
        res, _ = self._run(nodes, theta, MODE_COO, coo=coo)
        rows = np.concatenate([coo[0], m + np.arange(6)])
        cols = np.concatenate([coo[1], 12 * K + np.arange(6)])
        vals = np.concatenate([coo[2], self.model.theta_scale / self.prior_sigma])
        shape = (m + 6, 12 * K + 6)
        if np.all(rows[1:] >= rows[:-1]):
            # The kernel writes row by row with no repeated column: CSR directly, without
            # the sort of a COO conversion (2 s of a 60 s, 500 Hz estimate).
            indptr = np.searchsorted(rows, np.arange(shape[0] + 1))
            return res, sp.csr_matrix((vals, cols, indptr), shape=shape)
        return res, sp.csr_matrix((vals, (rows, cols)), shape=shape)
