"""control_msgs, shipped in bridge/interfaces/control_msgs, is upstream's release for ROS 2
Jazzy byte for byte (so its types are the ones real ROS 2 nodes use), and the venv's build of
it gives FollowJointTrajectory the expected RIHS01 type hashes, at build time (the installed
type description) and at run time (what rclpy's type support advertises on the graph).

The sha256 values were taken from the upstream tree itself (tag 5.8.0, commit
f901df2662f22a39a06aa04a85a34602c47e3cc0 of github.com/ros-controls/control_msgs, fetched
with `git show 5.8.0:<path> | sha256sum`), not from the copy they check.
"""

from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path

import pytest

from bridge.interfaces import INTERFACES_DIR, interface_packages

PACKAGE = INTERFACES_DIR / "control_msgs"

UPSTREAM_SHA256 = {
    "action/ExecuteMotionPrimitiveSequence.action":
        "76f105b8d00272e838051a070bf9a1662d3c1c8e48250486abc7525d530cd117",
    "action/FollowJointTrajectory.action":
        "31a124428ee490da22c15cc70a9ac2c89d07bbbba7d3bf370ca7596b229cb9f0",
    "action/GripperCommand.action":
        "a2b03986d92e1762e7deda6b2754347ffc53bd23546f2110b7a61e5d8049bebb",
    "action/JointTrajectory.action":
        "2b197658996475dfa353e5d0ee0b12ab21dda98a0e5831357782f8a4e010d1d2",
    "action/ParallelGripperCommand.action":
        "90e011bd5a1d5f3abc0ca879e7171569d356407a119f1fe9b4ba86c3efbd2b36",
    "action/PointHead.action":
        "4e976571d19a7c4cc19f2dad64fa8fe23f07c8c3450406fdee69af00a5c15694",
    "action/SingleJointPosition.action":
        "e2151938c8ac5fa5df3f82177bb656c3415360c3ed8ded7efef880350693aa44",
    "msg/AdmittanceControllerState.msg":
        "517bfbc04b1724a77e183797fa87c43d44de9d47541011bc61d4ed338e42f54e",
    "msg/BatteryStateArray.msg":
        "9d8c501ca0f230ddc06e2cb1747bd764b9f44e45581f5a52c21147115c135db5",
    "msg/DynamicInterfaceGroupValues.msg":
        "8f778add4a498a18f87a69150191d26f424d59796e7265c5aa643d34d4cc1fe8",
    "msg/DynamicInterfaceValues.msg":
        "3630b5b1769ffce337fc7a41294f72c21195da1e1e1f916ece2b5df84676b022",
    "msg/DynamicJointState.msg":
        "07cdcee131617ef68b66712f630c4f8fac585dc069a11d81400536832e3c6cfe",
    "msg/Float64Values.msg":
        "6bcd1799ecdbb23b4cf14f1e14edd6b8ba51d090f1b5c9ed4f7b77cd6baeb81f",
    "msg/GripperCommand.msg":
        "065fae74397f0a0e6c04646202276de57ac8360990a01bfeba62ced70edd9090",
    "msg/InterfaceValue.msg":
        "4eb240f11b44648befe94aec78dc65069ff836acedf88b9b32ea3b93f263bba0",
    "msg/JointComponentTolerance.msg":
        "6b09271d0f74e0a3a701f3ddb997b0ad4a588bdd9ab7d7899ddc70063ba924dd",
    "msg/JointControllerState.msg":
        "f7947e1b444745d450e812c7a042674b2396c7be71b6b38de32df63f58813bf4",
    "msg/JointJog.msg":
        "f0cf969f593fad6a394309e5db349683d191df954bdba7754a1b1f3355a3d818",
    "msg/JointTolerance.msg":
        "8208718f17c1b1feb9418c3ed7ca73d029566cbf298ecda819c9e0b78cb379d3",
    "msg/JointTrajectoryControllerState.msg":
        "7fb2953ccaae67b77ede3a32ef01376763e4aa133064d67d6929ef2fc16582b4",
    "msg/Keys.msg":
        "18e12b83ec2e28c87cc66b2262c62a16aadfdbcba425a10dce66cae416290b19",
    "msg/MecanumDriveControllerState.msg":
        "87dfa00289b8293abb7bb833cbbce6b094a89d5c648d5b8f6911ac490bc58afb",
    "msg/MotionArgument.msg":
        "2e064be1a63b234603ca43eec93638ba02b65b98d0309f761d6b92b1a64c7195",
    "msg/MotionPrimitive.msg":
        "a977e1c9a61babcd100c0c8af28e86bf47241ba13d33c5a57e7c4da0277f0420",
    "msg/MotionPrimitiveSequence.msg":
        "64cb1eef8c87766e61910e9d5f0a4ad0727c7b1f0bace580c373ef2f1c0df3f9",
    "msg/MultiDOFCommand.msg":
        "48c1108e8a12c827ec291e65cb24dfaabd8271b9af8e0f6dd1a25f64c23d8e7b",
    "msg/MultiDOFStateStamped.msg":
        "a5784df7da10cc1852352281561268bd3ff25c4c90b6472064cc70be9fdbba3c",
    "msg/PidState.msg":
        "79d5295f2e4e253c4c3dd6d2934819326c5dc0852d6fedf693303e6c8c86e6b5",
    "msg/SingleDOFState.msg":
        "df2efdbd3adc16e0185b4180ab90ece48a92bee8bbaa56657a949c53a28b3e2e",
    "msg/SingleDOFStateStamped.msg":
        "50bc523a1618f91962ecc66f4b622f736e34a2767626e8d17b3883a03bdbe7f1",
    "msg/SpeedScalingFactor.msg":
        "a42814bc2aeb923f9b2ec33a3408756076696bcf80b62c5af87de866d61b8055",
    "msg/SteeringControllerStatus.msg":
        "85d3d6529ee124b40019ebd290d6b4952e31eee3b837d8e7de8a4f8149121629",
    "msg/VDA5050SafetyState.msg":
        "c81beae81051562da5b5bb41166ca20892dfd0f7a9341575346e6fb57bb73147",
    "package.xml":
        "6528e5de12990c994292188620c836d5696b15ec62590e7610f07d92d1c89fa8",
    "srv/QueryCalibrationState.srv":
        "75070176d74fd6949a8fd6a1ba3ae6f23d24b165fda89986b3053012c480d3bc",
    "srv/QueryTrajectoryState.srv":
        "eb960a93fc4f6be927ee7e59415a830a69a80876ca8fdb4b1e5f177fe4cc03cf",
    "srv/SetOdometry.srv":
        "7bca2e47df644bb76ea2137f8163df6aecc9331cb851ac55fa3c019a2def5d98",
    "LICENSE":
        "1731298f899c65fa14cbdfe340b2c9c5fe17e9e219749e7fe2434e9374f66956",
}

# The RIHS01 hashes of the FollowJointTrajectory types built from those files against the
# ROS 2 Jazzy wheels (rosidl computes them from the definitions; comments do not count).
FJT_HASHES = {
    "control_msgs/action/FollowJointTrajectory":
        "RIHS01_738ebcb7a2d7cfa42f9f1001cc99ce3a4383d1cfe508015d9be8485e4b1c66f6",
    "control_msgs/action/FollowJointTrajectory_Goal":
        "RIHS01_8a9060704b269608f5a340934cc26e66869dd14bdac29e2e7fd9ec8b9882d205",
    "control_msgs/action/FollowJointTrajectory_Result":
        "RIHS01_8002e99ed2c14c6faa522f2a93c26d744c5982f254f9e98ff9c6f19789bdb220",
    "control_msgs/action/FollowJointTrajectory_Feedback":
        "RIHS01_3fd0aaecf71725121ae1ff7f01098a5e0da581e672be18a6b2c286cb43d96b49",
    "control_msgs/action/FollowJointTrajectory_FeedbackMessage":
        "RIHS01_80398fcb9674a79081a9906e2ccf0c804dd7cb15e22e362e606ee87186beab71",
}


def test_every_interface_file_is_upstreams() -> None:
    shipped = {str(p.relative_to(PACKAGE)) for p in PACKAGE.rglob("*")
               if p.is_file() and p.suffix in (".msg", ".action", ".srv", ".xml")}
    shipped.add("LICENSE")
    assert shipped == set(UPSTREAM_SHA256)
    for name, digest in UPSTREAM_SHA256.items():
        assert hashlib.sha256((PACKAGE / name).read_bytes()).hexdigest() == digest, name


def test_it_is_built_after_tf2_msgs() -> None:
    names = [p.name for p in interface_packages()]
    assert names.index("tf2_msgs") < names.index("control_msgs")


def test_the_built_type_description_has_the_expected_hashes() -> None:
    described = Path(sys.prefix) / "share" / "control_msgs" / "action" \
        / "FollowJointTrajectory.json"
    if not described.exists():
        pytest.skip(f"control_msgs is not built into this environment ({described} is absent)")
    hashes = {h["type_name"]: h["hash_string"]
              for h in json.loads(described.read_text())["type_hashes"]}
    for name, expected in FJT_HASHES.items():
        assert hashes[name] == expected, name


def test_rclpy_advertises_the_expected_hash_on_the_graph() -> None:
    rclpy = pytest.importorskip("rclpy")
    action = pytest.importorskip("control_msgs.action")
    from rclpy.action import ActionServer
    from rclpy.context import Context

    context = Context()
    rclpy.init(context=context)
    try:
        node = rclpy.create_node("hash_probe", context=context)
        server = ActionServer(node, action.FollowJointTrajectory, "/hash_probe/fjt",
                              execute_callback=lambda handle: None)
        infos = node.get_publishers_info_by_topic("/hash_probe/fjt/_action/feedback")
        assert len(infos) == 1
        assert str(infos[0].topic_type_hash) == \
            FJT_HASHES["control_msgs/action/FollowJointTrajectory_FeedbackMessage"]
        server.destroy()
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
