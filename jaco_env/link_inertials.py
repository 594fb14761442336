r"""The arm's link inertials: dm_control's (mass from each mesh) or Kinova's URDF (sensing factor (e)).

The Kinova assets shipped with ``dm_control`` give each link a mass and derive its centre of mass and
inertia from the mesh (MuJoCo's ``inertiafromgeom``). Kinova's own URDF for the 6-DOF Jaco 2 with the
three-finger hand (``kinova_description/urdf/j2n6s300.xacro``, mesh numbers of lines 43-45, values in
``kinova_description/urdf/kinova_inertial.xacro``, repository ``Kinovarobotics/kinova-ros`` at commit
``924781d3dfe241b2b94b3c72a804b80d3658cf02``) states them explicitly, each link's inertia as a solid
cylinder about the centre of mass:

.. math::

    I_{\text{axis}} = \tfrac12 m r^2, \qquad I_{\perp} = \tfrac1{12} m (3 r^2 + h^2).

=========  ==========================  =============  ===============================  ==========================
link       MJCF body (frame)           mass (kg)      centre of mass (link frame, m)   cylinder (h, r, axis,
                                       dm_control /                                    mass used for inertia)
                                       Kinova
=========  ==========================  =============  ===============================  ==========================
1          ``b_1``                     0.643 / 0.748  (0, -0.002, -0.0605)             0.14, 0.04, z, 0.7477
2          ``b_2``                     1.169 / 0.990  (0, -0.2065, -0.01)              0.35, 0.04, y, 0.99
3          ``b_3``                     0.673 / 0.676  (0, 0.081, -0.0086)              0.15, 0.03, y, 0.6763
4          ``b_4``                     0.221 / 0.426  (0, -0.037, -0.0642)             0.02, 0.04, z, 0.1785
5          ``b_5``                     0.221 / 0.426  (0, -0.037, -0.0642)             0.02, 0.04, z, 0.1785
6 (hand)   ``jaco_hand/hand``          0.547 / 0.990  (0, 0, -0.06)                    0.03, 0.04, z, 0.727
finger     each of the six finger      0.026 or       (0.022, 0, 0)                    0.03, 0.004, z, 0.01
           bodies                      0.013 / 0.010
=========  ==========================  =============  ===============================  ==========================

The Kinova file computes the wrist links' and the hand's inertia with a smaller mass than the link's
(0.1785 kg against 0.426 kg; 0.727 kg against 0.99 kg); this is reproduced as published, not
corrected. The frames agree: dm_control's bodies ``b_1`` .. ``b_6`` sit at the URDF's joint origins
(the same translations; the rotations of the URDF's ``rpy`` equal the bodies' quaternions to 4e-7),
with each joint about the body's z axis as in the URDF, and the hand's body frame is ``b_6``'s (the
wrist site's and the hand's rotations, each pi about (1, 1, 0)/sqrt(2), cancel). dm_control's finger
bodies have x along the finger (the distal link sits 0.044 m along it), as the URDF's; the finger
centre of mass is placed at the URDF's (0.022, 0, 0). Geometry, contacts and appearance stay
dm_control's: only the inertials change.
"""

from __future__ import annotations

import numpy as np
from dm_control import mjcf

#: Values of the option ``link_inertials`` (environments, scene, nominal URDF).
LINK_INERTIALS: tuple[str, ...] = ("dm_control", "kinova")

#: Kinova's inertials (``kinova_inertial.xacro``): MJCF body -> (mass, centre of mass, (h, r, axis, inertia mass)).
KINOVA: dict[str, tuple[float, tuple[float, float, float], tuple[float, float, str, float]]] = {
    "b_1": (0.7477, (0.0, -0.002, -0.0605), (0.14, 0.04, "z", 0.7477)),
    "b_2": (0.99, (0.0, -0.2065, -0.01), (0.35, 0.04, "y", 0.99)),
    "b_3": (0.6763, (0.0, 0.081, -0.0086), (0.15, 0.03, "y", 0.6763)),
    "b_4": (0.426367, (0.0, -0.037, -0.0642), (0.02, 0.04, "z", 0.1785)),
    "b_5": (0.426367, (0.0, -0.037, -0.0642), (0.02, 0.04, "z", 0.1785)),
    "jaco_hand/hand": (0.99, (0.0, 0.0, -0.06), (0.03, 0.04, "z", 0.727)),
}
#: Each finger link (proximal and distal): mesh numbers 57 and 58 of ``kinova_inertial.xacro``.
KINOVA_FINGER = (0.01, (0.022, 0.0, 0.0), (0.03, 0.004, "z", 0.01))
FINGER_BODIES: tuple[str, ...] = tuple(f"jaco_hand/b_finger{tip}_{k}" for k in (1, 2, 3) for tip in ("", "_tip"))


def cylinder_inertia(height: float, radius: float, axis: str, mass: float) -> np.ndarray:
    """Principal moments (kg m^2, about x, y, z) of a solid cylinder along ``axis`` (``"x"``, ``"y"`` or ``"z"``)."""
    along = 0.5 * mass * radius**2
    across = mass * (3.0 * radius**2 + height**2) / 12.0
    return np.array([along if a == axis else across for a in "xyz"])


def check_link_inertials(value: object, none_allowed: bool = False) -> str:
    """``value`` if it is one of :data:`LINK_INERTIALS`; naming ``link_inertials`` otherwise, ``TypeError`` (not a
    string) or ``ValueError`` (another name). ``none_allowed`` only adds "or None" to the message, for callers that
    take ``None`` before they check."""
    expected = f"{LINK_INERTIALS} or None" if none_allowed else f"{LINK_INERTIALS}"
    if not isinstance(value, str):
        raise TypeError(f"link_inertials must be one of {expected}, got {type(value).__name__} {value!r}")
    if value not in LINK_INERTIALS:
        raise ValueError(f"link_inertials must be one of {expected}, got {value!r}")
    return value


def resolve(value: object, sensor_pipeline: object) -> str:
    """The option ``link_inertials`` resolved: a name of :data:`LINK_INERTIALS` as given, or, for ``None``, the
    pipeline's own: ``"kinova"`` under the full ``"jaco2"`` preset (a name or the equal ``SignalPipeline``),
    ``"dm_control"`` otherwise."""
    if value is not None:
        return check_link_inertials(value, none_allowed=True)
    from jaco_env.signal_pipeline import SignalPipeline

    jaco2 = sensor_pipeline == "jaco2" or sensor_pipeline == SignalPipeline.jaco2()
    return "kinova" if jaco2 else "dm_control"


def apply(arm: mjcf.RootElement, link_inertials: str) -> None:
    """Give the arm (with its hand attached) the chosen link inertials; ``"dm_control"`` leaves it as it is.

    Each listed body gets an explicit ``<inertial>``, which MuJoCo uses instead of the geoms' masses.
    """
    if check_link_inertials(link_inertials) == "dm_control":
        return
    for name, (mass, com, (h, r, axis, m_i)) in [*KINOVA.items(), *((f, KINOVA_FINGER) for f in FINGER_BODIES)]:
        body = arm.find("body", name)
        if body is None:
            raise ValueError(f"link_inertials: the arm has no body {name!r} (dm_control's Kinova assets changed?)")
        body.add("inertial", pos=list(com), mass=mass, diaginertia=cylinder_inertia(h, r, axis, m_i).tolist())
