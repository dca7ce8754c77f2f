"""Launches the BEVT-rs tracking node.

    ros2 launch bevt_node bevt.launch.py
    ros2 launch bevt_node bevt.launch.py params_file:=/etc/bevt/node.yaml namespace:=uav1 \
        image_topic:=/camera/color/image_raw respawn:=true

Arguments:
  params_file  parameters file (default: the installed share/bevt_node/config/node.yaml,
               every value at its default; its section is `bevt_node:` or `/**:`)
  namespace    ROS namespace of the node and its topics (default: none)
  image_topic  the camera's raw image topic that the node's `image_raw` is remapped to; the
               compressed input follows it (`<image_topic>/compressed`)
  respawn      restart the node 2 s after it exits (true/false, default true): the node
               exits non-zero when one of its threads dies, so a respawn recovers the fault

Written against launch / launch_ros as in Humble and later: `respawn` takes a literal there
(a substitution only since Jazzy), so the argument selects one of two Node actions.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition, UnlessCondition
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare

RESPAWN_DELAY_S = 2.0

ARGUMENTS = [
    (
        "params_file",
        PathJoinSubstitution([FindPackageShare("bevt_node"), "config", "node.yaml"]),
        "parameters file (ROS 2 format: bevt_node: ros__parameters: ...)",
    ),
    ("namespace", "", "namespace of the node and its topics"),
    ("image_topic", "image_raw", "camera raw image topic (its /compressed follows)"),
    ("respawn", "true", "restart the node when it exits (true/false)"),
]


def _node(respawn):
    condition = IfCondition if respawn else UnlessCondition
    return Node(
        package="bevt_node",
        executable="bevt_node",
        name="bevt_node",
        namespace=LaunchConfiguration("namespace"),
        parameters=[LaunchConfiguration("params_file")],
        remappings=[("image_raw", LaunchConfiguration("image_topic"))],
        output="screen",
        respawn=respawn,
        respawn_delay=RESPAWN_DELAY_S if respawn else None,
        condition=condition(LaunchConfiguration("respawn")),
    )


def generate_launch_description():
    arguments = [
        DeclareLaunchArgument(name, default_value=default, description=doc)
        for name, default, doc in ARGUMENTS
    ]
    return LaunchDescription(arguments + [_node(True), _node(False)])
