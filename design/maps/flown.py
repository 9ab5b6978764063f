"""Where the wind acts on a real vehicle: the airframe correction of the learning law.

The Theorem (paper Sec. III, docs/theory.md section 2) assumes the paper's loop
``y = P{u2 + d}`` (Sec. II): the disturbance adds to the command. On a vehicle the wind
pushes the airframe; the command first passes the attitude loop. Write the model as

    P_hat = A_hat * R,     R = 1/s^2  (rigid body)   or   R = 1/(s (s + a))  (rigid body with drag)

with ``A_hat`` the attitude chain (command -> achieved acceleration) and ``R`` the path from
an acceleration on the airframe to the position. The same airframe acceleration ``d`` is
then ``A_j^{-1}{d}`` at vehicle j's command: vehicle j-1's data reconstruct *its* command-side
equivalent and vehicle j needs its own. With the wind maps ``Gd_j = Gd_j,paper A_j^{-1}`` in
the Theorem's ``L1_j = (Gf_j Gd_{j-1})^{-1} Gd_j`` the paper's L1 gains exactly the factor

    W = A_hat_{j-1} / A_hat_j = (P_hat_{j-1} / P_hat_j) (R_j / R_{j-1})

(:func:`airframe_path_filter`); around a cycle of the fleet the factors multiply to 1.
Without it, on the nonlinear quadrotors of :mod:`ilcdob.vehicles.quadrotor`, UAV3 learning
from UAV1 (attitude time constants 0.139 vs 0.100 s) kept ~5 mm of error at the fixed point
(noise-free, scenario 1), and the full run left 1-6 % of the DOB-only RMSE instead of
0.5-3 %.

Supported model structures (:func:`rigid_body_split`):

* two integrators (``b0 / (s^2 (s + a0))`` and any attitude chain behind ``1/s^2``): a
  vehicle without drag;
* one integrator and at least one real stable pole: a drag-damped vehicle
  (``b0 / (s (s + a_drag)(s + a_att))``); the slowest real pole is taken as the drag pole
  ``a`` of ``R``, every other pole and zero belongs to the attitude chain.

Other structures (no integrator, three or more, or one integrator without a real pole) have
no rigid body to split off and are refused with the reason. The correction assumes ``d`` is
the acceleration (force per unit mass) the wind gives every vehicle alike; one wind acting
through airframes of different drag per unit mass gives them different accelerations, which
no model of the command path alone can correct.

Wind through the drag (``disturbance="wind"``, beyond the paper). What the vehicles share is the
wind *velocity* ``w``, not an acceleration: with drag per unit mass ``a`` the air moving past the
airframe pushes it with ``a (w - v)``. The ``- a v`` part is the drag pole of the identified model
(``R = 1/(s (s + a))``); what remains, ``a w``, is the disturbance on the airframe. So the
airframe acceleration that vehicle j-1's trial reconstructs, ``a_{j-1} w``, stands for the wind
``w``, and vehicle j meets ``a_j w``: the learning filter gains the factor ``a_j / a_{j-1}``
besides ``W``, the ratio of the two models' drag poles (:func:`airframe_path_filter` with
``wind=True``). It needs the drag-damped structure in both models (a model with two
integrators has no drag, and a wind velocity would give it no acceleration). On rotorpy's
multirotors (a simulator nobody here wrote; rotor and parasitic drag on the airspeed),
identified from chirp flights in still air (drag poles 0.29 and 0.51 1/s, where rotorpy's rotor
drag alone gives 0.24 and 0.45), a 2 m/s sinusoidal wind at 0.94 rad/s left 0.48 (crazyflie ->
hummingbird) and 0.88 (hummingbird -> crazyflie) of the DOB-only error with the paper's law, and
0.11 / 0.11 through the drag ratio (20 s hover, ``tests/test_vehicle_interface.py``).

:func:`model_attitude` gives a model's ``A_hat`` in discrete time, with which a command-side
estimate is expressed as the airframe acceleration it stands for. The learning law itself,
with its robustness filter and trial horizon, is :mod:`ilcdob.design.filters.band`.
"""

from __future__ import annotations

import numpy as np
from scipy import signal as sps

from ilcdob.errors import SpecError
from ilcdob.loop import LoopSystem
from ilcdob.specs import PlantSpec
from ilcdob.channel_loop import ChannelLoop

__all__ = ["rigid_body_split", "model_attitude", "airframe_path_filter", "disturbance_path", "check_disturbance",
           "DISTURBANCE_PATHS"]

#: Where the disturbance acts: ``command`` (the paper's loop, added to the command), ``airframe`` (an
#: acceleration on the rigid body, behind the attitude chain) or ``wind`` (a wind velocity through each
#: airframe's drag, module docstring).
DISTURBANCE_PATHS = ("command", "airframe", "wind")

_STRUCTURES = ("two integrators (rigid body 1/s^2), or one integrator and a real stable pole (rigid body with "
               "drag 1/(s (s + a)))")


def check_disturbance(disturbance: object) -> str:
    """Return ``disturbance`` if it is one of :data:`DISTURBANCE_PATHS`, else raise :class:`SpecError`.

    Parameters
    ----------
    disturbance : object
        Where the disturbance acts, as given.
    """
    if disturbance not in DISTURBANCE_PATHS:
        raise SpecError(f"`disturbance`: got {disturbance!r}, expected one of {list(DISTURBANCE_PATHS)} (command: "
                        "added to the command as in the paper's loop; airframe: an acceleration on the rigid body; "
                        "wind: a wind velocity through each airframe's drag)")
    return disturbance


def rigid_body_split(plant: PlantSpec, name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Split ``P_hat = A_hat R`` into the attitude chain and the rigid body (module docstring).

    Parameters
    ----------
    plant : PlantSpec
        The model ``P_hat`` (continuous time).
    name : str
        The system's name, for messages.

    Returns
    -------
    (num, den, rigid) : numpy.ndarray
        ``A_hat = num/den`` and the denominator of ``R`` (``[1, 0, 0]`` or ``[1, a, 0]``),
        s-polynomials, highest power first.

    Raises
    ------
    SpecError
        A structure without a rigid body to split off, or a zero at the origin.
    """
    num = np.trim_zeros(np.asarray(plant.num, float), "f")
    den = np.trim_zeros(np.asarray(plant.den, float), "f")
    k = 0
    while den.size > 1 and den[-1] == 0.0:
        den, k = den[:-1], k + 1
    what = f"model of {name!r}: got P_hat = {list(plant.num)}/{list(plant.den)} with {k} integrator(s)"
    if num[-1] == 0.0:
        raise SpecError(f"{what} and a zero at s = 0; the airframe correction needs {_STRUCTURES}")
    if k == 2:
        return num, den, np.array([1.0, 0.0, 0.0])
    if k == 1:
        poles = np.roots(den) if den.size > 1 else np.zeros(0)
        real = poles[(np.abs(poles.imag) <= 1e-9 * np.maximum(1.0, np.abs(poles))) & (poles.real < 0)].real
        if real.size:
            a = -float(real[np.argmax(real)])  # the slowest real pole: drag
            rest, rem = np.polydiv(den, [1.0, a])
            if np.max(np.abs(rem), initial=0.0) <= 1e-8 * np.max(np.abs(den)):
                return num, rest, np.array([1.0, a, 0.0])
    raise SpecError(f"{what}; the airframe correction needs {_STRUCTURES}. Fit one of these structures "
                    "(ilcdob identify --integrators 2, or --integrators 1 with a pole more), or learn with the "
                    "disturbance at the command (--disturbance command)")


def model_attitude(loop: LoopSystem) -> tuple[np.ndarray, np.ndarray, int]:
    """The model's attitude chain ``A_hat = P_hat / R`` under zero-order hold.

    Parameters
    ----------
    loop : LoopSystem
        The loop whose model ``P_hat`` (``loop.spec.nominal_plant``) is ``A_hat R``
        (:func:`rigid_body_split`).

    Returns
    -------
    (b, a, delay) : (numpy.ndarray, numpy.ndarray, int)
        ``z^-1`` coefficients for :func:`scipy.signal.lfilter` and the model's input delay
        in whole samples (rounded).

    Raises
    ------
    SpecError
        The model has no rigid body to split off.
    """
    num, den, _ = rigid_body_split(loop.spec.nominal_plant, loop.name)
    b, a, _ = sps.cont2discrete((num, den), loop.ts, method="zoh")
    return np.atleast_1d(np.squeeze(b)), np.atleast_1d(a), int(round(loop.spec.nominal_plant.delay / loop.ts))


#: Smallest drag pole (1/s) of a vehicle learned from in wind (``wind=True``): a time constant beyond 50 s is longer
#: than identification flights resolve (a pole that slow fits as well as an integrator), and the wind velocity is
#: reconstructed by dividing by it. Multirotors' drag poles are 0.1-1 1/s.
MIN_WIND_DRAG = 0.02


def airframe_path_filter(source: LoopSystem | ChannelLoop, target: LoopSystem | ChannelLoop,
                         wind: bool = False) -> np.ndarray:
    """Discrete ``W = A_hat_{j-1} / A_hat_j`` (Tustin) as second-order sections: the
    airframe-wind correction of the learning filter (module docstring); with ``wind`` times
    ``a_j / a_{j-1}``, the ratio of the models' drag poles.

    Parameters
    ----------
    source : LoopSystem or ChannelLoop
        Loop of vehicle j-1 (the trial learned from), built from its model; a vehicle on its own
        controller through its identified airframe (:attr:`~ilcdob.channel_loop.ChannelLoop.airframe`).
    target : LoopSystem or ChannelLoop
        Loop of vehicle j (the one that flies the learning signal).
    wind : bool
        The disturbance is a wind velocity acting through each airframe's drag.

    Returns
    -------
    numpy.ndarray
        Sections ``[b0, b1, b2, 1, a1, a2]`` of W for :func:`scipy.signal.sosfilt` (from rest).

    Raises
    ------
    SpecError
        A model without a rigid body to split off (with ``wind``: without a drag pole), different
        model delays, ``A_hat_j`` with a zero in the closed right half plane (W would be unstable), or
        a vehicle on its own controller without an identified airframe.
    """
    ps, pt = _airframe_model(source), _airframe_model(target)
    ns, ds, rs = rigid_body_split(ps, source.name)
    nt, dt_, rt = rigid_body_split(pt, target.name)
    gain = 1.0
    if wind:
        for loop, rigid in ((source, rs), (target, rt)):
            if rigid[1] <= 0:
                raise SpecError(f"model of {loop.name!r}: two integrators, no drag pole; a wind velocity gives such a "
                                "model no acceleration. Identify it with one integrator and a drag pole "
                                "(ilcdob identify --integrators 1), or learn with --disturbance airframe")
        if rs[1] < MIN_WIND_DRAG:
            raise SpecError(f"model of {source.name!r}: drag pole {rs[1]:.3g} 1/s (time constant {1 / rs[1]:.0f} s) is "
                            f"below {MIN_WIND_DRAG:g} 1/s: its trial cannot sense the wind, and dividing by its drag "
                            f"would amplify the trial {rt[1] / rs[1]:.0f} times. Learn from a vehicle with "
                            "measurable drag, or with --disturbance airframe")
        gain = float(rt[1] / rs[1])
    if abs(ps.delay - pt.delay) > 1e-9:
        raise SpecError(f"models of {source.name!r} and {target.name!r}: delays {ps.delay:g} s and "
                        f"{pt.delay:g} s differ; the airframe correction needs equal model delays")
    zt = np.roots(nt) if nt.size > 1 else np.zeros(0)
    if np.any(zt.real >= 0):
        raise SpecError(f"model of {target.name!r}: zeros {zt} in the closed right half plane; "
                        "A_hat_j-1/A_hat_j would be unstable")
    b, a = sps.bilinear(gain * np.polymul(ns, dt_), np.polymul(ds, nt), fs=1.0 / source.ts)
    return sps.tf2sos(np.atleast_1d(b), np.atleast_1d(a))


def disturbance_path(source: LoopSystem | ChannelLoop, target: LoopSystem | ChannelLoop, disturbance: str
                     ) -> tuple[np.ndarray | None, dict]:
    """The correction a design learns through for a checked ``disturbance`` (:func:`check_disturbance`), and
    the ``disturbance`` entry of its ``filters.json``.

    Parameters
    ----------
    source, target : LoopSystem or ChannelLoop
        Vehicles j-1 and j (:func:`airframe_path_filter`).
    disturbance : {"command", "airframe", "wind"}
        Where the disturbance acts.

    Returns
    -------
    (numpy.ndarray or None, dict)
        ``W``'s sections (None on the command, where no correction is needed) and ``{"at": disturbance}``
        with ``W``'s ``{"sos": ...}`` where there is one.

    Raises
    ------
    SpecError
        As :func:`airframe_path_filter`.
    """
    if disturbance == "command":
        return None, {"at": disturbance}
    path = airframe_path_filter(source, target, disturbance == "wind")
    return path, {"at": disturbance, "W": {"sos": path.tolist()}}


def _airframe_model(loop: LoopSystem | ChannelLoop) -> PlantSpec:
    """The model ``P_hat = A_hat R`` of a loop's airframe: the paper loop's plant model, or a vehicle on
    its own controller's identified airframe."""
    if not isinstance(loop, ChannelLoop):
        return loop.spec.nominal_plant
    if loop.airframe is None:
        raise SpecError(f"vehicle {loop.name!r}: no identified airframe (commanded acceleration -> position), and a "
                        "disturbance on the airframe or in wind reaches it through it; identify its channel from "
                        "flights that log the commanded acceleration, or learn with disturbance='command'")
    return loop.airframe
