"""Run-time composition of the pouring scene with :mod:`dm_control.mjcf`.

The scene is the bare Jaco 2 arm of :func:`jaco_env.robot.build_arm_mjcf` (Kinova
assets shipped with ``dm_control``; nothing is copied into this repository) plus

* a **bottle rigidly attached to the hand**: the bottle is a child body of the
  hand (no joint), i.e. a perfect, slip-free grasp. Its axis is perpendicular to
  the hand's approach axis, so that rolling the wrist tips it. The bottle is an
  open cylinder (wide mouth) made of ``BOTTLE_N_WALLS`` box staves and a disc.
* an **extra rigid payload** (body ``payload`` inside the bottle's bottom) whose
  mass is set per episode (``set_payload_mass``) and is never observed;
* ``n_marbles`` free-floating spheres (placed inside the bottle at reset by the
  environment);
* a table (top at z = 0, the robot base stands on it), a floor, and a jar (open
  cylinder of ``JAR_N_WALLS`` staves) whose position is set from the task;
* the actuators: in ``"torque"`` mode the firmware torque loop, one actuator per
  joint whose command (ctrl range the Kinova torque limits) reaches the joint
  through the loop's first-order lag; in ``"velocity"`` mode the emulated Kinova
  firmware joint velocity loop on the same torque loop (see :func:`add_actuators`);
* the link-side joint torque sensors (:func:`jaco_env.robot.add_torque_sensors`).

Contact filtering (``contype``/``conaffinity`` bit 4): marbles collide with each
other, the bottle, the jar, the table and the floor; the arm (bits 1-2, from the
Kinova assets) never touches bottle, jar, table or marbles, so tracking errors
show up as spilled marbles, not as collisions.
"""

from __future__ import annotations

import numpy as np
from dm_control import mjcf

from jaco_env import robot
from jaco_env.checks import check_mass

# --- geometry (m, kg) -------------------------------------------------------------
BOTTLE_INNER_RADIUS = 0.035
BOTTLE_WALL = 0.006
BOTTLE_BOTTOM = -0.07  # bottle-frame z of the inner bottom (grip at z = 0)
BOTTLE_TOP = 0.10  # bottle-frame z of the mouth
BOTTLE_MASS = 0.20  # glass bottle
BOTTLE_N_WALLS = 12
MARBLE_RADIUS = 0.0075
MARBLE_MASS = 0.005  # a 15 mm glass marble weighs about 4.5-5 g
#: Jar inner radius: sized so that tracking accuracy decides the pour (payload 1.2 kg, mouth
#: ``pour_height`` 5 cm above the rim, see ``scripts/pour_separation.py``): with the oracle's mouth
#: error while pouring (~0.2-0.5 cm mean) every marble lands, with the nominal rigid-body
#: feedforward's (~1-1.7 cm) most miss on 6 of 7 tasks, with PD only (~1.6-3.4 cm) nearly all.
#: (35 mm: the nominal feedforward poured 100% on most tasks; 25-26 mm: the oracle lost a few.)
JAR_INNER_RADIUS = 0.027
JAR_HEIGHT = 0.12
JAR_WALL = 0.006
JAR_N_WALLS = 16
#: Radius (m) of the robot's base around the z axis at the origin: the farthest vertex of the Kinova
#: base mesh (dm_control's ``kinova/jaco_arm.xml``, geom ``base``) lies 0.0493 m from the axis in the
#: compiled scene (``tests/test_env_api.py`` checks the bound against the mesh).
BASE_RADIUS = 0.050
#: Total payload held in the hand (bottle + marbles + extra), Jaco 2 datasheet maximum.
MAX_PAYLOAD = 1.6
#: Most marbles a pouring env holds in its bottle.
MAX_MARBLES = 60


def bottle_mass(n_marbles: int) -> float:
    """Mass (kg) of the bottle holding ``n_marbles`` marbles: the least payload in the hand."""
    return BOTTLE_MASS + n_marbles * MARBLE_MASS


def check_rigid_payload_mass(value: object, what: str) -> float:
    """``value`` as the rigid payload in the hand (kg) of ``JacoPayload-v0``: at least the empty bottle's mass, at most
    :data:`MAX_PAYLOAD` (``TypeError`` / ``ValueError`` naming ``what``)."""
    return check_mass(value, BOTTLE_MASS, MAX_PAYLOAD, what)


def check_payload_mass(value: object, fixed_mass: float, what: str) -> float:
    """``value`` as the total payload in the hand (kg): at least 1 g above ``fixed_mass`` (:func:`bottle_mass`), at
    most :data:`MAX_PAYLOAD` (``TypeError`` / ``ValueError`` naming ``what``)."""
    return check_mass(value, fixed_mass + 1e-3, MAX_PAYLOAD, what)


#: Gains of the emulated firmware velocity loop (per joint), which sits on the closed torque loop
#: (``robot`` docstring): tau_c = KV (v - qd) + KI (q_ref - q), q_ref the integral of the command v.
#: Derived, not tuned: with the joint inertia I seen by each joint (``robot.DESIGN_INERTIA``: links
#: at the home pose with a 1 kg payload plus the residual armature), the loop ``I s^2 + KV s + KI``
#: gets a natural frequency of 15 rad/s and unit damping: KI = I 15^2, KV = 2 I 15. MuJoCo
#: integrates the velocity term implicitly (``implicitfast``), so it is stable at the physics rate.
FIRMWARE_KV = 2.0 * 15.0 * robot.DESIGN_INERTIA
FIRMWARE_KI = 15.0**2 * robot.DESIGN_INERTIA

MARBLE_BIT = 4

# --- names in the composed model (the arm is attached as ``jaco_arm``, its hand as ``jaco_hand``) ----
ARM_PREFIX = "jaco_arm/"
HAND_PREFIX = ARM_PREFIX + "jaco_hand/"
BOTTLE_BODY = HAND_PREFIX + "bottle"
PAYLOAD_BODY = HAND_PREFIX + "payload"
MOUTH_SITE = HAND_PREFIX + "bottle_mouth"

#: Radius (m) of the solid sphere that stands for the extra rigid payload in its inertia, and the
#: radius of gyration (m) of a pile of marbles lumped into the payload body (the inertia barely
#: matters at the hand).
PAYLOAD_SPHERE_RADIUS = 0.03
MARBLE_PILE_GYRATION = 0.02


def payload_inertia(extra_mass: float, marble_mass: float = 0.0) -> float:
    """Principal moment of inertia (kg m^2, the same about every axis) of the payload body.

    The extra rigid mass is a solid sphere of radius ``PAYLOAD_SPHERE_RADIUS``; marbles lumped into
    the body (``marble_mass``, kg; the oracle's rigid model) add a point mass at
    ``MARBLE_PILE_GYRATION``. The environment and the oracle both take the payload inertia from here.
    """
    return 0.4 * extra_mass * PAYLOAD_SPHERE_RADIUS**2 + marble_mass * MARBLE_PILE_GYRATION**2


def _ring(body: mjcf.Element, n: int, r_in: float, wall: float, z0: float, z1: float, rgba, mass: float,
          prefix: str) -> None:
    """Add ``n`` box staves forming an open cylinder (inner radius ``r_in``) between z0 and z1."""
    half_h = (z1 - z0) / 2
    # Half-width so neighbouring staves touch at the inner radius.
    half_w = (r_in + wall) * np.tan(np.pi / n) + 1e-3
    for k in range(n):
        a = 2 * np.pi * k / n
        c = r_in + wall / 2
        body.add(
            "geom", name=f"{prefix}_wall{k}", type="box", size=[wall / 2, half_w, half_h],
            pos=[c * np.cos(a), c * np.sin(a), z0 + half_h], euler=[0, 0, a], rgba=rgba,
            mass=mass / n, contype=MARBLE_BIT, conaffinity=0, group=1,
        )


def _attach_bottle(arm: mjcf.RootElement, *, with_payload: bool = True) -> mjcf.Element:
    hand = arm.find("body", "jaco_hand/hand")
    grip = arm.find("site", "jaco_hand/gripsite")
    # Bottle frame: origin at the grip site, z (bottle axis, towards the mouth) along the grip
    # site's x axis, i.e. perpendicular to the approach axis (grip z).
    quat = robot.quat_mul(np.asarray(grip.quat, float), robot.axis_angle_quat([0, 1, 0], np.pi / 2))
    bottle = hand.add("body", name="bottle", pos=grip.pos, quat=quat)
    rgba = [0.3, 0.6, 0.3, 0.45]
    _ring(bottle, BOTTLE_N_WALLS, BOTTLE_INNER_RADIUS, BOTTLE_WALL, BOTTLE_BOTTOM, BOTTLE_TOP, rgba,
          0.75 * BOTTLE_MASS, "bottle")
    bottle.add("geom", name="bottle_base", type="cylinder",
               size=[BOTTLE_INNER_RADIUS + BOTTLE_WALL, BOTTLE_WALL / 2],
               pos=[0, 0, BOTTLE_BOTTOM - BOTTLE_WALL / 2], rgba=rgba, mass=0.25 * BOTTLE_MASS,
               contype=MARBLE_BIT, conaffinity=0, group=1)
    bottle.add("site", name="bottle_mouth", pos=[0, 0, BOTTLE_TOP], size=[0.01], rgba=[1, 0, 0, 1])
    bottle.add("site", name="bottle_center", pos=[0, 0, 0.5 * (BOTTLE_TOP + BOTTLE_BOTTOM)], size=[0.005])
    if with_payload:
        # Extra rigid mass under the marbles; its mass is overwritten per episode.
        payload = bottle.add("body", name="payload", pos=[0, 0, BOTTLE_BOTTOM - BOTTLE_WALL])
        payload.add("inertial", pos=[0, 0, 0], mass=0.5, diaginertia=[1e-4, 1e-4, 1e-4])
    return bottle


def add_actuators(root: mjcf.RootElement, arm: mjcf.RootElement, control_mode: str) -> None:
    """Add the six joint actuators.

    ``"torque"``: the closed firmware torque loop: ctrl = commanded joint torque, clipped to
    ``robot.TORQUE_LIMITS``, reaching the joint through a first-order lag of time constant
    ``robot.TORQUE_LOOP_TAU`` (MuJoCo ``filterexact`` dynamics; the actuator's activation is the
    torque the loop delivers). The residual rotor inertia and friction are on the joints.

    ``"velocity"``: the emulated Kinova firmware joint-velocity loop, evaluated by MuJoCo at
    the physics rate: per joint a ``velocity`` actuator ``KV (v - qd)`` and an integrating
    position actuator ``KI (q_ref - q)`` whose activation ``q_ref`` integrates the command ``v``
    (a PI velocity loop); both get the same command, and the joint's ``actuatorfrcrange`` clips
    their sum to the Kinova torque limits. This torque command drives the same closed torque
    loop (residual rotor inertia and friction on the joints); the loop's 5 ms lag is neglected
    here, being well above the velocity loop's 15 rad/s.
    """
    if control_mode not in ("torque", "velocity"):
        raise ValueError(f"control_mode must be 'torque' or 'velocity', got {control_mode!r}")
    for i, name in enumerate(robot.JOINT_NAMES):
        joint = arm.find("joint", name)
        lim = robot.TORQUE_LIMITS[i]
        joint.actuatorfrcrange = [-lim, lim]
        if control_mode == "torque":
            root.actuator.add("general", name=f"tau_{i + 1}", joint=joint, ctrllimited=True,
                              ctrlrange=[-lim, lim], dyntype="filterexact",
                              dynprm=[robot.TORQUE_LOOP_TAU], gaintype="fixed", gainprm=[1.0],
                              biastype="none")
        else:
            vlim = robot.VELOCITY_LIMITS[i]
            root.actuator.add("velocity", name=f"vel_{i + 1}", joint=joint, kv=FIRMWARE_KV[i],
                              ctrllimited=True, ctrlrange=[-vlim, vlim])
    if control_mode == "velocity":
        for i, name in enumerate(robot.JOINT_NAMES):
            joint = arm.find("joint", name)
            vlim = robot.VELOCITY_LIMITS[i]
            kw = {}
            if joint.range is not None:
                kw = dict(actlimited=True, actrange=list(joint.range))
            root.actuator.add("general", name=f"int_{i + 1}", joint=joint, dyntype="integrator",
                              gaintype="fixed", gainprm=[FIRMWARE_KI[i]], biastype="affine",
                              biasprm=[0, -FIRMWARE_KI[i], 0], ctrllimited=True,
                              ctrlrange=[-vlim, vlim], **kw)


def build_scene(
    *,
    kind: str = "pour",
    n_marbles: int = 30,
    control_mode: str | None = "torque",
    timestep: float = 0.002,
    jar_pos: np.ndarray | None = None,
    link_inertials: str = "dm_control",
    delayed_reads: list[tuple[str, str, int]] | None = None,
) -> mjcf.RootElement:
    """Compose the scene.

    Args:
        kind: ``"pour"`` (bottle, marbles, jar, table) or ``"payload"`` (bottle with rigid
            payload only; also used as the kinematic/inverse-dynamics model).
        n_marbles: number of marbles (``"pour"`` only).
        control_mode: ``"torque"``, ``"velocity"`` or ``None`` (no actuators).
        timestep: physics step (s).
        jar_pos: initial jar position (m, jar bottom centre); the env moves it per task.
        link_inertials: the arm's link inertials, ``"dm_control"`` or ``"kinova"``
            (:mod:`jaco_env.link_inertials`).
        delayed_reads: delayed joint sensors of a sensing pipeline, ``(name, sensor type, lead in physics
            steps)`` (:meth:`jaco_env.signal_pipeline.PipelineState.reads`,
            :func:`jaco_env.robot.add_delayed_reads`); none by default.
    """
    if kind not in ("pour", "payload"):
        raise ValueError(f"kind must be 'pour' or 'payload', got {kind!r}")
    root = mjcf.RootElement(model=f"jaco_{kind}")
    root.compiler.angle = "radian"
    root.option.timestep = timestep
    root.option.integrator = "implicitfast"
    root.option.cone = "elliptic"
    # CG instead of the default Newton solver: with ~30 free marbles (nv ~ 190) Newton's
    # per-step Hessian factorisation dominates; CG reaches the same tolerance ~2x faster here.
    root.option.solver = "CG"
    root.option.noslip_iterations = 0
    getattr(root.visual, "global").offwidth = 1024
    getattr(root.visual, "global").offheight = 1024
    root.asset.add("texture", name="grid", type="2d", builtin="checker", rgb1=[0.35, 0.35, 0.38],
                   rgb2=[0.3, 0.3, 0.33], width=256, height=256)
    root.asset.add("material", name="grid", texture="grid", texrepeat=[8, 8])
    root.worldbody.add("light", pos=[0.5, -0.5, 2.5], dir=[-0.2, 0.2, -1], diffuse=[0.8, 0.8, 0.8])
    root.worldbody.add("light", pos=[-0.5, 0.5, 2.0], dir=[0.2, -0.2, -1], diffuse=[0.4, 0.4, 0.4])
    root.worldbody.add("geom", name="floor", type="plane", size=[3, 3, 0.1], pos=[0, 0, -0.75],
                       material="grid", contype=MARBLE_BIT, conaffinity=0)
    root.worldbody.add("geom", name="table", type="box", size=[0.9, 0.9, 0.02], pos=[0.2, 0, -0.02],
                       rgba=[0.55, 0.42, 0.3, 1], contype=MARBLE_BIT, conaffinity=0)
    root.worldbody.add("camera", name="overview", pos=[1.6, -1.3, 1.2], xyaxes=[0.63, 0.77, 0, -0.35, 0.29, 0.89])

    arm = robot.build_arm_mjcf(link_inertials=link_inertials)
    robot.add_torque_sensors(arm)
    if delayed_reads:
        robot.add_delayed_reads(arm, delayed_reads, timestep)
    _attach_bottle(arm, with_payload=True)
    root.attach(arm)
    if control_mode is not None:
        add_actuators(root, arm, control_mode)

    if kind == "pour":
        jar_pos = np.zeros(3) if jar_pos is None else np.asarray(jar_pos, float)
        jar = root.worldbody.add("body", name="jar", pos=jar_pos)
        _ring(jar, JAR_N_WALLS, JAR_INNER_RADIUS, JAR_WALL, 0.0, JAR_HEIGHT, [0.3, 0.4, 0.8, 0.5], 0.5, "jar")
        jar.add("geom", name="jar_base", type="cylinder", size=[JAR_INNER_RADIUS + JAR_WALL, 0.003],
                pos=[0, 0, 0.003], rgba=[0.3, 0.4, 0.8, 1], contype=MARBLE_BIT, conaffinity=0)
        for k in range(n_marbles):
            m = root.worldbody.add("body", name=f"marble{k}", pos=[0.0, 0.0, -0.5 - 0.02 * k])
            m.add("freejoint", name=f"marble{k}")
            m.add("geom", name=f"marble{k}", type="sphere", size=[MARBLE_RADIUS], mass=MARBLE_MASS,
                  rgba=[0.9, 0.5, 0.1, 1], contype=MARBLE_BIT, conaffinity=MARBLE_BIT, condim=3,
                  friction=[0.6, 0.005, 0.0001], solref=[0.005, 1])
    return root


def compile_model(root: mjcf.RootElement):
    """Compile an MJCF root to a ``mujoco.MjModel`` (XML string + mesh assets in memory)."""
    import mujoco

    return mujoco.MjModel.from_xml_string(root.to_xml_string(), root.get_assets())


def lumped_marble_com_offset() -> np.ndarray:
    """Bottle-frame position of the marble pile's centre of mass at rest (upright bottle)."""
    return np.array([0.0, 0.0, BOTTLE_BOTTOM + 0.04])
