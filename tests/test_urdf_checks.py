"""A URDF that parses but describes a broken robot is refused, naming the file and the element; an odd one is
named in a warning (cascgp.urdf_checks). A URDF without such problems says nothing."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from cascgp.rbd import RigidBodyModel
from tests.test_rbd_joints import arm_urdf, write

ARM = arm_urdf(("revolute",) * 3)


@pytest.mark.parametrize("old, new, match", [
    ('<mass value="0.9"/>', '<mass value="heavy"/>',
     r"the parser dropped an <inertial> it could not read \(urdfdom: Inertial: mass \[heavy\] is not a float; Could "
     r"not parse inertial element for Link \[l2\]\)"),
    ('<mass value="0.9"/>', '<mass value="nan"/>', r"urdfdom: Inertial: mass \[nan\] is not a float"),
    ('<mass value="0.9"/>', '<mass value="-0.9"/>', r"link 'l2' has a negative mass \(-0.9 kg\)"),
    # the parser kept the first and dropped the second, silently
    ('<mass value="0.9"/>', '<mass value="0.9"/></inertial><inertial><mass value="2.0"/>',
     r"link 'l2' has 2 <inertial> elements \(URDF allows one"),
    ('iyy="0.018000000000000002"', 'iyy="-0.018"', r"link 'l2' has an inertia with a negative principal moment"),
    ('<axis xyz="1 0 0"/>', '<axis xyz="0 0 0"/>', r"joint 'j3' has an axis of zero length \('0 0 0'\)"),
    ('</robot>', '<joint name="extra" type="fixed"><parent link="base"/><child link="l3"/></joint></robot>',
     r"link 'l3' is the child of two joints \('j3' and 'extra'\)"),
    ('<axis xyz="1 0 0"/>', '<axis xyz="1 0 0"/><mimic joint="ghost"/>',
     r"joint 'j3' mimics 'ghost', which the URDF does not have"),
    ('<axis xyz="1 0 0"/>', '<axis xyz="1 0 0"/><mimic joint="j3"/>', r"joint 'j3' mimics itself"),
])
def test_a_broken_urdf_is_refused_naming_the_file_and_the_element(tmp_path: Path, old: str, new: str,
                                                                   match: str) -> None:
    assert ARM.count(old) == 1
    text = ARM.replace(old, new)
    with pytest.raises(ValueError, match=r"broken\.urdf'.*" + match):
        RigidBodyModel.from_urdf(write(tmp_path, "broken.urdf", text))


def test_a_model_files_copy_of_its_urdf_is_read_as_it_was_saved() -> None:
    """from_urdf_text (a model file's embedded URDF) parses without the file checks: a file saved before them
    loads as it was saved (its check predictions say whether it is the same model)."""
    rbd = RigidBodyModel.from_urdf_text(ARM.replace('<mass value="0.9"/>', '<mass value="-0.9"/>'))
    assert rbd.dof == 3


def test_an_unreadable_visual_is_passed_on_not_refused(tmp_path: Path) -> None:
    """urdfdom reads a link's inertial first; a visual it cannot read loses only geometry: the same dynamics."""
    visual = '<visual><geometry><capsule radius="0.1" length="0.2"/></geometry></visual></link>'
    at = ARM.index("</link>", ARM.index('<link name="l2">'))
    text = ARM[:at] + visual + ARM[at + len("</link>"):]
    rbd = RigidBodyModel.from_urdf(write(tmp_path, "capsule.urdf", text))
    ref = RigidBodyModel.from_urdf(write(tmp_path, "arm.urdf", ARM))
    q = np.linspace(-1.0, 1.0, 9).reshape(3, 3)
    np.testing.assert_array_equal(rbd.inverse_dynamics(q, q, q), ref.inverse_dynamics(q, q, q))


def test_joints_that_move_no_mass_are_named_in_a_warning(tmp_path: Path) -> None:
    """No <inertial> beyond j2: j3 moves nothing and its rigid-body torque is 0; j1 and j2 move l2."""
    text = ARM.replace(ARM[ARM.index('<link name="l3">'):ARM.index("</link>", ARM.index('<link name="l3">')) + 7],
                       '<link name="l3"/>')
    with pytest.warns(UserWarning, match=r"massless\.urdf': joints that move no mass or inertia .*: 'j3'$"):
        rbd = RigidBodyModel.from_urdf(write(tmp_path, "massless.urdf", text))
    assert rbd.dof == 3


def test_a_sound_urdf_says_nothing(tmp_path: Path) -> None:
    import jaco_env

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        RigidBodyModel.from_urdf(write(tmp_path, "arm.urdf", ARM))
        RigidBodyModel.from_urdf(write(tmp_path, "gripper.urdf", arm_urdf(("continuous", "revolute", "prismatic"),
                                                                          fingers="prismatic")))
        RigidBodyModel.from_urdf(jaco_env.NOMINAL_URDF)
