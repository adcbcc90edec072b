"""The force and torque balance: θ by equation error, chosen from the flight itself.

The model (paper Eqs. drag, newton, euler) is linear in c_T, c_T c_D and c_M given the
rotor speeds and the vehicle's states, and Euler's equation solved per axis is linear in
the ratios c_T/j_x, c_T/j_y, c_M/j_z and the gyroscopic coefficients. The measured side
(the pose differentiated) and the model's columns go through one smoother
(`mavsysid.estimation.signals`): ``rows`` builds them, ``choices`` picks the band, window
and rotor-to-pose offset from the flight and regresses, ``regression`` is the weighted
least squares with its Newey–West σ and reverse value, ``theta`` maps coefficients to θ
and widens σ, ``fit`` answers per parameter with the held-out check. The same rows serve
the held-out check, ``diagnose``'s residuals and the report's wrench figure.
"""

__all__: list[str] = []
