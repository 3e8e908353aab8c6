"""The library of canonical mechanisms.

Each factory returns a validated :class:`~optkin.mechanism.Mechanism`; tests, benchmarks and
``problems/`` share them. :data:`LIBRARY` maps names to factories (used by problem files).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from ._checks import as_float, as_matrix, as_vector, check_number
from ._checks import show as _show
from .errors import MechanismError
from .mechanism import Leg, Mechanism
from .mechanism.legs import degenerate_points

__all__ = [
    "rpr3", "rpr4", "rrr3", "five_bar", "four_bar", "stewart_gough", "delta", "sr400", "akr3000",
    "upu3", "rps3", "prr3", "hexa", "pus6", "psp3", "LIBRARY",
]


def _points(a: Any, shape: tuple[int, int], name: str) -> np.ndarray:
    try:
        got = np.shape(a)
    except (ValueError, TypeError, RecursionError):  # ragged nested lists
        got = None
    if got != shape:
        raise MechanismError(f"{name}: expected an array of shape {shape}, got "
                             + (f"shape {got}" if got is not None else _show(a)), path=(name,))
    try:
        return as_matrix(a, name, shape, path=(name,))
    except MechanismError as e:
        raise MechanismError(f"{name}: expected finite numbers; {str(e)[len(name) + 2:]}",
                             path=(name,)) from None


def _lengths(v: Any, n: int, name: str) -> np.ndarray:
    try:
        a = as_vector(v, name, path=(name,))
    except MechanismError:
        raise MechanismError(f"{name}: expected a positive number or {n} of them, got "
                             f"{_show(v)}", path=(name,)) from None
    if a.size == 1 and np.ndim(v) == 0:
        a = np.full(n, float(a[0]))
    if a.shape != (n,):
        raise MechanismError(f"{name}: expected a positive number or {n} of them, got shape "
                             f"{a.shape}", path=(name,))
    if np.any(a <= 0):
        raise MechanismError(f"{name}: lengths must be positive and finite, got {a.tolist()}",
                             path=(name, int(np.flatnonzero(a <= 0)[0])))
    return a


def _positive(name: str, v: Any) -> float:
    return check_number(v, name, lo=0.0, lo_open=True, want="a positive length", path=(name,))


def _finite(name: str, v: Any) -> float:
    return as_float(v, name, path=(name,))



def _platform(legs: list[dict[str, Any]], platform: str, **kw: Any) -> Mechanism:
    """``Mechanism.from_legs`` for a factory whose arguments are ``base`` and ``platform``:
    attachment points that leave no regular configuration are reported against them."""
    bad = degenerate_points([Leg.from_spec(leg, i) for i, leg in enumerate(legs)], platform)
    if bad is not None:
        key, idx, text = bad
        rows = ", ".join(str(i) for i in idx)
        key = key or "base"
        raise MechanismError(f"{key}: rows {rows}: {text}", path=(key,))
    return Mechanism.from_legs(legs, platform, **kw)


def rpr3(base: Any, platform: Any, home: Sequence[float] | None = None) -> Mechanism:
    """Planar 3-RPR: base (3, 2) joint centres, platform (3, 2) in the platform frame.

    q_a = the three leg lengths; the pose is the platform frame (x, y, phi).

    Parameters
    ----------
    base : array (3, 2)
        Base joint centres A_i.
    platform : array (3, 2)
        Platform joint centres B_i in the platform frame.
    home : sequence of 3 floats, optional
        Task coordinates (x, y, phi) used as the default guess of :func:`optkin.forward`.

    Returns
    -------
    Mechanism

    Examples
    --------
    >>> m = rpr3([[0, 0], [1, 0], [0, 1]], [[0, 0], [0.2, 0], [0, 0.2]])
    >>> m.active_names
    ('L1.rho', 'L2.rho', 'L3.rho')
    """
    b = _points(base, (3, 2), "base")
    p = _points(platform, (3, 2), "platform")
    legs = [{"type": "RPR", "base": b[i], "platform": p[i]} for i in range(3)]
    return _platform(legs, "planar", name="3-RPR", home=home)


def rpr4(base: Any, platform: Any, home: Sequence[float] | None = None) -> Mechanism:
    """Planar 4-RPR: a redundantly actuated platform (four actuated legs, three dof).

    base (4, 2) joint centres, platform (4, 2) in the platform frame; q_a = the four leg
    lengths (they must be consistent for the platform to close: the direct model solves
    the four closure rows in the least-squares sense). ``mech.redundant`` is True.

    Parameters
    ----------
    base : array (4, 2)
        Base joint centres.
    platform : array (4, 2)
        Platform joint centres in the platform frame.
    home : sequence of 3 floats, optional
        Task coordinates (x, y, phi) of the default guess.

    Returns
    -------
    Mechanism

    Examples
    --------
    >>> m = rpr4([[0, 0], [1, 0], [1, 1], [0, 1]], [[-0.1, -0.1], [0.1, -0.1], [0.1, 0.1], [-0.1, 0.1]])
    >>> m.dof, m.n_actuated, m.redundant
    (3, 4, True)
    """
    b = _points(base, (4, 2), "base")
    p = _points(platform, (4, 2), "platform")
    legs = [{"type": "RPR", "base": b[i], "platform": p[i]} for i in range(4)]
    return _platform(legs, "planar", name="4-RPR", home=home, redundant=True)


def rrr3(
    base: Any, platform: Any, proximal: Any, distal: Any, home: Sequence[float] | None = None
) -> Mechanism:
    """Planar 3-RRR with actuated base revolutes; link lengths scalars or one per leg.

    Parameters
    ----------
    base : array (3, 2)
        Actuated base revolutes.
    platform : array (3, 2)
        Platform revolutes in the platform frame.
    proximal, distal : float or 3 floats
        Lengths of the base-side and platform-side links (positive).
    home : sequence of 3 floats, optional
        Task coordinates (x, y, phi) of the default guess.

    Returns
    -------
    Mechanism

    Examples
    --------
    >>> m = rrr3([[0, 0], [1, 0], [0.5, 0.9]], [[-0.1, -0.05], [0.1, -0.05], [0, 0.1]], 0.4, 0.4)
    >>> m.active_names
    ('L1.theta1', 'L2.theta1', 'L3.theta1')
    """
    b = _points(base, (3, 2), "base")
    p = _points(platform, (3, 2), "platform")
    l1 = _lengths(proximal, 3, "proximal")
    l2 = _lengths(distal, 3, "distal")
    legs = [
        {"type": "RRR", "base": b[i], "platform": p[i], "lengths": [l1[i], l2[i]]}
        for i in range(3)
    ]
    return _platform(legs, "planar", name="3-RRR", home=home)


def five_bar(L0: float, L1: float, L2: float, L3: float, L4: float) -> Mechanism:
    """The RR-RRR five-bar of Chablat and Wenger 1998.

    Base joints A = (0, 0) and B = (L0, 0); ``|AC|`` = L1, ``|CP|`` = L2, ``|PD|`` = L3, ``|DB|`` = L4;
    q_a = (theta1 at A, theta2 at B), angles from the x axis; the end effector is P.

    Parameters
    ----------
    L0, L1, L2, L3, L4 : float
        Positive lengths ``|AB|``, ``|AC|``, ``|CP|``, ``|PD|``, ``|DB|``.

    Returns
    -------
    Mechanism

    Examples
    --------
    P = (4.5, 6) is at distance 7.5 < L1 + L2 from A and B: two elbows per leg.

    >>> import optkin
    >>> m = five_bar(9, 8, 5, 5, 8)
    >>> m.active_names, len(optkin.inverse(m, [4.5, 6.0]))
    (('L1.theta1', 'L2.theta1'), 4)
    """
    L0 = _positive("L0", L0)
    L1, L2, L3, L4 = (_positive(n, v) for n, v in zip(("L1", "L2", "L3", "L4"), (L1, L2, L3, L4)))
    legs = [
        {"type": "RRR", "base": [0.0, 0.0], "platform": [0.0, 0.0], "lengths": [L1, L2]},
        {"type": "RRR", "base": [L0, 0.0], "platform": [0.0, 0.0], "lengths": [L4, L3]},
    ]
    reach = min(L1 + L2, L3 + L4)
    return Mechanism.from_legs(legs, "planar_point", name="five-bar",
                               home=[L0 / 2, 0.6 * reach])


def four_bar(L1: float, L2: float, L3: float, L4: float) -> Mechanism:
    """The planar four-bar of Modern Robotics 7.3, as a Khalil table with one loop.

    Ground A = (0, 0) to D = (L4, 0); input crank L1 at angle ``theta`` (actuated);
    coupler L2; rocker L3 at D at absolute angle ``phi``. The loop is cut at the
    coupler-rocker joint (frame 4, partner frame 5 on the rocker). End effector: the rocker
    frame (task ``rz``, so ``inverse`` gives the crank angles for a rocker angle).

    Parameters
    ----------
    L1, L2, L3, L4 : float
        Positive lengths of the crank, coupler, rocker and ground.

    Returns
    -------
    Mechanism

    Examples
    --------
    Crank at 1 rad: the rocker tip is on two circles; the open mode has phi = 1.7275693...
    (problems/four_bar.toml).

    >>> import optkin
    >>> m = four_bar(1.0, 2.0, 2.0, 2.5)
    >>> r = optkin.forward(m, [1.0])
    >>> m.joint_names, round(float(r.q[2]), 6)
    (('theta', 'theta2', 'phi', 'theta4'), 1.727569)
    """
    L1, L2, L3, L4 = (_positive(n, v) for n, v in zip(("L1", "L2", "L3", "L4"), (L1, L2, L3, L4)))
    rows = [
        dict(a=0, mu=1, sigma=0, gamma=0, b=0, alpha=0, d=0, theta="theta", r=0),
        dict(a=1, mu=0, sigma=0, gamma=0, b=0, alpha=0, d="L1", theta="theta2", r=0),
        dict(a=0, mu=0, sigma=0, gamma=0, b=0, alpha=0, d="L4", theta="phi", r=0),
        dict(a=2, mu=0, sigma=0, gamma=0, b=0, alpha=0, d="L2", theta="theta4", r=0),
        dict(a=3, mu=0, sigma=2, gamma=0, b=0, alpha=0, d="L3", theta=0, r=0),
    ]
    return Mechanism.from_khalil(
        rows, loops=1, params={"L1": L1, "L2": L2, "L3": L3, "L4": L4}, end_effector=3,
        name="four-bar", task=("rz",), home={"theta2": -0.5, "phi": 1.5, "theta4": 1.5},
    )


def stewart_gough(base: Any, platform: Any, home: Sequence[float] | None = None) -> Mechanism:
    """6-6 Stewart-Gough platform (6-UPS): base (6, 3), platform (6, 3) in the platform frame.

    q_a = the six leg lengths; pose (x, y, z, roll, pitch, yaw).

    Parameters
    ----------
    base : array (6, 3)
        Base U-joint centres.
    platform : array (6, 3)
        Platform S-joint centres in the platform frame.
    home : sequence of 6 floats, optional
        Task coordinates of the default guess.

    Returns
    -------
    Mechanism

    Examples
    --------
    >>> import numpy as np
    >>> a = np.linspace(0, 2 * np.pi, 7)[:-1]
    >>> b = np.c_[np.cos(a), np.sin(a), 0 * a]
    >>> m = stewart_gough(b, 0.5 * np.c_[np.cos(a + 0.3), np.sin(a + 0.3), 0 * a])
    >>> m.dof, m.task
    (6, ('x', 'y', 'z', 'roll', 'pitch', 'yaw'))
    """
    b = _points(base, (6, 3), "base")
    p = _points(platform, (6, 3), "platform")
    legs = [{"type": "UPS", "base": b[i], "platform": p[i]} for i in range(6)]
    return _platform(legs, "spatial", name="Stewart-Gough", home=home)


def delta(
    base_radius: float = 0.2,
    platform_radius: float = 0.05,
    upper: float = 0.3,
    lower: float = 0.8,
) -> Mechanism:
    """The Delta robot: three RUS legs at 0, 120 and 240 degrees.

    Base revolute i at ``base_radius`` (cos a_i, sin a_i, 0) with its axis tangent to the
    base circle; the arm of length ``upper`` points radially outwards at theta = 0 and down
    for theta > 0. Each parallelogram forearm (length ``lower``) is modelled as S-S pairs
    that keep the platform parallel to the base, so the platform translates (x, y, z); its
    joint i sits at ``platform_radius`` (cos a_i, sin a_i, 0).

    Parameters
    ----------
    base_radius, platform_radius : float
        Radii of the base revolutes and of the platform joints (positive).
    upper, lower : float
        Lengths of the arms and of the parallelogram forearms (positive).

    Returns
    -------
    Mechanism

    Examples
    --------
    >>> m = delta()
    >>> m.dof, m.task, m.active_names
    (3, ('x', 'y', 'z'), ('L1.theta', 'L2.theta', 'L3.theta'))
    """
    Rb = _positive("base_radius", base_radius)
    rp = _positive("platform_radius", platform_radius)
    la = _positive("upper", upper)
    lb = _positive("lower", lower)
    legs = []
    for k in range(3):
        a = 2 * np.pi * k / 3
        u = np.array([np.cos(a), np.sin(a), 0.0])
        legs.append(
            {
                "type": "RUS",
                "base": Rb * u,
                "platform": rp * u,
                "lengths": [la, lb],
                "axis": [-np.sin(a), np.cos(a), 0.0],
                "arm": u,
            }
        )
    z = -np.sqrt(max(lb**2 - (Rb + la - rp) ** 2, 0.25 * lb**2))
    return Mechanism.from_legs(legs, "spatial_translational", name="Delta", home=[0.0, 0.0, z])


def sr400(
    d2: float = 0.15, d3: float = 0.6, d4: float = 0.1, d8: float = 0.25, rl4: float = 0.65
) -> Mechanism:
    """The Acma SR400 of Table 7.1 (Khalil & Dombre 2002): six actuated revolutes and a parallelogram.

    d9 = d3 and d10 = -d8 as in the table; the loop is cut at joint 9 (frames 9 and 10).
    The end effector is frame 6.

    Parameters
    ----------
    d2, d3, d4, d8, rl4 : float
        The lengths of Table 7.1 (finite).

    Returns
    -------
    Mechanism

    Examples
    --------
    >>> m = sr400()
    >>> m.dof, m.active_names
    (6, ('theta1', 'theta2', 'theta4', 'theta5', 'theta6', 'theta7'))
    """
    params = {"d2": _finite("d2", d2), "d3": _finite("d3", d3), "d4": _finite("d4", d4),
              "d8": _finite("d8", d8), "RL4": _finite("rl4", rl4)}
    h = np.pi / 2
    rows = [
        dict(a=0, mu=1, sigma=0, gamma=0, b=0, alpha=0, d=0, theta="theta1", r=0),
        dict(a=1, mu=1, sigma=0, gamma=0, b=0, alpha=-h, d="d2", theta="theta2", r=0),
        dict(a=2, mu=0, sigma=0, gamma=0, b=0, alpha=0, d="d3", theta="theta3", r=0),
        dict(a=3, mu=1, sigma=0, gamma=0, b=0, alpha=-h, d="d4", theta="theta4", r="RL4"),
        dict(a=4, mu=1, sigma=0, gamma=0, b=0, alpha=h, d=0, theta="theta5", r=0),
        dict(a=5, mu=1, sigma=0, gamma=0, b=0, alpha=-h, d=0, theta="theta6", r=0),
        dict(a=1, mu=1, sigma=0, gamma=0, b=0, alpha=-h, d="d2", theta="theta7", r=0),
        dict(a=7, mu=0, sigma=0, gamma=0, b=0, alpha=0, d="d8", theta="theta8", r=0),
        dict(a=8, mu=0, sigma=0, gamma=0, b=0, alpha=0, d="d3", theta="theta9", r=0),
        dict(a=3, mu=0, sigma=2, gamma=h, b=0, alpha=0, d="-d8", theta=0, r=0),
    ]
    home = {"theta3": np.pi / 2, "theta8": 0.0, "theta9": np.pi}
    return Mechanism.from_khalil(rows, loops=1, params=params, end_effector=6, name="SR400",
                                 home=home)


def akr3000(
    d3: float = 0.25,
    d4: float = 0.45,
    d7: float = 0.9,
    r8: float = 0.7,
    d13: float = 0.3,
    d14: float = 0.3,
    gamma13: float = 0.4,
    gamma14: float = 1.2,
) -> Mechanism:
    """The AKR-3000 painting robot of Table 7.2 (Khalil & Dombre 2002): two loops, 12 joints.

    Active: theta1, r5, r6 (the two cylinders), theta8, theta9, theta10; passive theta2,
    theta3, theta4, theta7; cut joints theta11 (loop of links 5 and 7) and theta12 (loop of
    links 2 and 6), partner frames 13 and 14. End effector: frame 10.

    Parameters
    ----------
    d3, d4, d7, r8, d13, d14 : float
        The lengths of Table 7.2 (finite).
    gamma13, gamma14 : float
        The angles gamma of the partner frames 13 and 14 (rad).

    Returns
    -------
    Mechanism

    Examples
    --------
    >>> m = akr3000()
    >>> m.dof, m.active_names, len(m.joint_names)
    (6, ('theta1', 'r5', 'r6', 'theta8', 'theta9', 'theta10'), 12)
    """
    params = {k: _finite(k, v) for k, v in dict(d3=d3, d4=d4, d7=d7, r8=r8, d13=d13, d14=d14,
                                                g13=gamma13, g14=gamma14).items()}
    h = np.pi / 2
    rows = [
        dict(a=0, mu=1, sigma=0, gamma=0, b=0, alpha=0, d=0, theta="theta1", r=0),
        dict(a=1, mu=0, sigma=0, gamma=0, b=0, alpha=h, d=0, theta="theta2", r=0),
        dict(a=1, mu=0, sigma=0, gamma=0, b=0, alpha=h, d="d3", theta="theta3", r=0),
        dict(a=1, mu=0, sigma=0, gamma=0, b=0, alpha=h, d="d4", theta="theta4", r=0),
        dict(a=3, mu=1, sigma=1, gamma=0, b=0, alpha=-h, d=0, theta=0, r="r5"),
        dict(a=4, mu=1, sigma=1, gamma=0, b=0, alpha=-h, d=0, theta=0, r="r6"),
        dict(a=2, mu=0, sigma=0, gamma=0, b=0, alpha=0, d="d7", theta="theta7", r=0),
        dict(a=7, mu=1, sigma=0, gamma=0, b=0, alpha=-h, d=0, theta="theta8", r="r8"),
        dict(a=8, mu=1, sigma=0, gamma=0, b=0, alpha=h, d=0, theta="theta9", r=0),
        dict(a=9, mu=1, sigma=0, gamma=0, b=0, alpha=-h, d=0, theta="theta10", r=0),
        dict(a=5, mu=0, sigma=0, gamma=0, b=0, alpha=h, d=0, theta="theta11", r=0),
        dict(a=6, mu=0, sigma=0, gamma=0, b=0, alpha=h, d=0, theta="theta12", r=0),
        dict(a=7, mu=0, sigma=2, gamma="g13", b=0, alpha=0, d="d13", theta=0, r=0),
        dict(a=2, mu=0, sigma=2, gamma="g14", b=0, alpha=0, d="d14", theta=0, r=0),
    ]
    # the cylinders r5 and r6 only extend: negative lengths are not physical postures
    return Mechanism.from_khalil(rows, loops=2, params=params, end_effector=10, name="AKR-3000",
                                 limits={"r5": (0.0, None), "r6": (0.0, None)})


#: name -> factory, for problem files and the command line.


def _circle(radius: float, angles: np.ndarray) -> np.ndarray:
    return np.c_[radius * np.cos(angles), radius * np.sin(angles), np.zeros(len(angles))]


def _triad() -> tuple[np.ndarray, np.ndarray]:
    """Radial and tangent unit vectors (3, 3) at 0, 120 and 240 degrees in the xy-plane."""
    a = 2 * np.pi * np.arange(3) / 3
    return (np.c_[np.cos(a), np.sin(a), np.zeros(3)], np.c_[-np.sin(a), np.cos(a), np.zeros(3)])


def upu3(base_radius: float = 1.0, platform_radius: float = 0.5) -> Mechanism:
    """Tsai's 3-UPU translational manipulator (Tsai, ARK 1996).

    Three UPU legs at 0, 120 and 240 degrees: each base universal joint turns first about
    the tangent of the base circle (fixed to the base), then about a horizontal radial
    axis; the platform joint's axes are the same two in reverse order, so the two inner
    axes stay parallel, as do the outer ones (Tsai's condition): in the translational
    operation mode the platform only translates. q_a = the three leg lengths; the platform
    is spatial (its orientation is an unknown the legs keep at the identity).

    Parameters
    ----------
    base_radius, platform_radius : float
        Radii of the circles of the base and platform joint centres.

    Examples
    --------
    >>> import numpy as np, optkin
    >>> m = upu3(1.0, 0.5)
    >>> r = optkin.forward(m, [1.2, 1.2, 1.2], guess=[0, 0, 1.0, 0, 0, 0])
    >>> bool(r.success), round(float(r.pose[2, 3]), 9), bool(np.allclose(r.pose[:3, :3], np.eye(3)))
    (True, 1.090871211, True)
    """
    R = _positive("base_radius", base_radius)
    r = _positive("platform_radius", platform_radius)
    u, t = _triad()
    legs = [{"type": "UPU", "base": (R * u[i]).tolist(), "platform": (r * u[i]).tolist(),
             "axis": t[i].tolist(), "arm": (-u[i]).tolist()} for i in range(3)]
    return Mechanism.from_legs(legs, "spatial", name="3-UPU")


def rps3(base_radius: float = 1.0, platform_radius: float = 0.5) -> Mechanism:
    """The 3-RPS parallel manipulator: three legs at 0, 120 and 240 degrees, each a
    passive revolute on the base whose axis is the tangent of the base circle (the leg
    turns in the vertical plane through the base centre), an actuated prismatic joint and
    a spherical joint on the platform. Three degrees of freedom (heave, roll, pitch with
    coupled parasitic motions); q_a = the three leg lengths.

    Examples
    --------
    >>> import optkin
    >>> m = rps3(1.0, 0.5)
    >>> len(m.active_names), optkin.dof(m).mobility
    (3, 3)
    """
    R = _positive("base_radius", base_radius)
    r = _positive("platform_radius", platform_radius)
    u, t = _triad()
    legs = [{"type": "RPS", "base": (R * u[i]).tolist(), "platform": (r * u[i]).tolist(),
             "axis": t[i].tolist()} for i in range(3)]
    return Mechanism.from_legs(legs, "spatial", name="3-RPS")


def prr3(base: Any, directions: Any, platform: Any, distal: Any) -> Mechanism:
    """The planar 3-PRR: three actuated sliders, each carrying a revolute joint linked by
    a distal bar of length ``distal`` to a revolute on the platform.

    Parameters
    ----------
    base : array (3, 2)
        The sliders' reference points (s = 0).
    directions : array (3, 2)
        The sliders' unit directions.
    platform : array (3, 2)
        The platform joint centres in the platform frame.
    distal : float or array (3,)
        Distal bar lengths.

    Examples
    --------
    >>> import optkin
    >>> m = prr3([[0, 0], [2, 0], [1, 2]], [[1, 0], [0, 1], [-1, 0]],
    ...          [[-0.2, -0.1], [0.2, -0.1], [0.0, 0.2]], 1.5)
    >>> len(optkin.inverse(m, [1.0, 1.0, 0.1]))   # two postures per leg
    8
    """
    b = _points(base, (3, 2), "base")
    d = _points(directions, (3, 2), "directions")
    p = _points(platform, (3, 2), "platform")
    lens = _lengths(distal, 3, "distal")
    legs = [{"type": "PRR", "base": b[i], "platform": p[i], "direction": d[i],
             "lengths": [lens[i]]} for i in range(3)]
    return Mechanism.from_legs(legs, "planar", name="3-PRR")


def hexa(base_radius: float = 0.5, platform_radius: float = 0.15, crank: float = 0.35,
         rod: float = 0.8, base_spread: float = 0.3, platform_spread: float = 0.25
         ) -> Mechanism:
    """The Hexa (Pierrot 1991; Chablat & Wenger 1998, Fig. 4): six RUS legs in three pairs.

    Leg i turns an arm (``crank``) about the tangent of the base circle at angle
    ``2 pi k / 3 +- base_spread``; a rod of length ``rod`` joins the arm's tip to the
    platform point at ``2 pi k / 3 +- platform_spread`` on the platform circle. Six
    degrees of freedom, 2^6 = 64 working modes (Chablat & Wenger 1998, Example 1); q_a = the arm angles
    (0: arm radial outwards, turning downwards as theta grows).

    Examples
    --------
    >>> import optkin
    >>> m = hexa()
    >>> len(optkin.working_modes(m))
    64
    """
    Rb = _positive("base_radius", base_radius)
    rp = _positive("platform_radius", platform_radius)
    la = _positive("crank", crank)
    lb = _positive("rod", rod)
    sb = _finite("base_spread", base_spread)
    sp = _finite("platform_spread", platform_spread)
    k = np.repeat(2 * np.pi * np.arange(3) / 3, 2)
    sign = np.tile([-1.0, 1.0], 3)
    ab, ap = k + sign * sb, k + sign * sp
    legs = []
    for i in range(6):
        u = np.array([np.cos(ab[i]), np.sin(ab[i]), 0.0])
        t = np.array([-np.sin(ab[i]), np.cos(ab[i]), 0.0])
        legs.append({"type": "RUS", "base": (Rb * u).tolist(),
                     "platform": [rp * np.cos(ap[i]), rp * np.sin(ap[i]), 0.0],
                     "lengths": [la, lb], "axis": t.tolist(), "arm": u.tolist()})
    return _platform(legs, "spatial", name="Hexa")


def pus6(rails: Any = None, direction: Any = (1.0, 0.0, 0.0), platform: Any = None,
         rod: Any = 1.0) -> Mechanism:
    """A 6-PUS hexaglide: six sliders on parallel rails carry universal joints; rods of
    length ``rod`` join them to spherical joints on the platform.

    Parameters
    ----------
    rails : array (6, 3), optional
        Each slider's point at s = 0 (default: rails at y = +-0.15, +-0.5, +-0.85 on z = 0,
        staggered along x).
    direction : array (3,)
        The rails' unit direction (shared).
    platform : array (6, 3), optional
        Platform joint centres in the platform frame (default: a hexagon of radius 0.25).
    rod : float or array (6,)
        Rod lengths.

    Examples
    --------
    >>> import optkin
    >>> m = pus6()
    >>> len(optkin.inverse(m, [0.0, 0.0, 0.6, 0.0, 0.0, 0.0]))   # two postures per leg
    64
    """
    if rails is None:
        rails = [[-0.3, -0.85, 0], [-0.3, 0.85, 0], [0.3, -0.5, 0], [0.3, 0.5, 0],
                 [0.0, -0.15, 0], [0.0, 0.15, 0]]
    if platform is None:
        a = np.array([-100, 100, -40, 40, -140, 140]) * np.pi / 180
        platform = np.c_[0.25 * np.cos(a), 0.25 * np.sin(a), np.zeros(6)]
    b = _points(rails, (6, 3), "rails")
    p = _points(platform, (6, 3), "platform")
    d = as_vector(direction, "direction", 3, path=("direction",))
    lens = _lengths(rod, 6, "rod")
    legs = [{"type": "PUS", "base": b[i], "platform": p[i], "direction": d,
             "lengths": [lens[i]]} for i in range(6)]
    return Mechanism.from_legs(legs, "spatial", name="hexaglide")


def psp3(base_radius: float = 1.0, platform_radius: float = 0.4) -> Mechanism:
    """The 3-PSP of Modern Robotics Exercise 7.5: three vertical actuated sliders at 0,
    120 and 240 degrees on the base circle carry spherical joints, each on a slider of the
    platform along its radial direction.

    Three degrees of freedom (6 (8 - 1 - 9) + 15 = 3, Grubler); q_a = the slider heights.

    Examples
    --------
    >>> import optkin
    >>> m = psp3()
    >>> optkin.dof(m).mobility
    3
    """
    R = _positive("base_radius", base_radius)
    r = _positive("platform_radius", platform_radius)
    a = 2 * np.pi * np.arange(3) / 3
    u = np.c_[np.cos(a), np.sin(a), np.zeros(3)]
    legs = [{"type": "PSP", "base": (R * u[i]).tolist(), "platform": (r * u[i]).tolist(),
             "direction": [0.0, 0.0, 1.0], "axis": u[i].tolist()} for i in range(3)]
    return Mechanism.from_legs(legs, "spatial", name="3-PSP")


LIBRARY: dict[str, Callable[..., Mechanism]] = {
    "rpr3": rpr3,
    "rpr4": rpr4,
    "rrr3": rrr3,
    "five_bar": five_bar,
    "four_bar": four_bar,
    "stewart_gough": stewart_gough,
    "delta": delta,
    "sr400": sr400,
    "akr3000": akr3000,
    "upu3": upu3,
    "rps3": rps3,
    "prr3": prr3,
    "hexa": hexa,
    "pus6": pus6,
    "psp3": psp3,
}
