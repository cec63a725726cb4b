"""The typed JSON command schema spoken over OpenIGTLink COMMAND / RTS_COMMAND.

A request is a COMMAND message (header v2): its NAME is the op (``"create_subscriber"``),
its text a JSON object with the op's arguments, optionally ``"schema": 1``. The answer is an
RTS_COMMAND with the same command ID and NAME, a JSON `Reply`, and metadata ``Status``
(``SUCCESS``/``FAIL``, what 3D Slicer's ``igtlioCommand::GetSuccessful`` checks) plus
``ErrorMessage`` on failure. protocol/README.md lists every op with examples.

One frozen dataclass per op, declaring what it writes, creates, removes and touches
(`protocol.commands.op`); an IntEnum `ErrorCode` and one `CommandError` subclass per way a
request can be refused, each naming the field, what was expected and what came.

The package, by job:

    errors      error codes and exceptions
    wire        JSON text, limits, reply metadata
    fields      the field reader (`Args`)
    values      QoS, Stamp, ParameterValue, RobotSource, matrices
    types       the one grammar of ROS type names
    results     the typed results' base (`Result`: a reply's JSON object and its reader) and
                those shared by several areas; `Answered` for ops a client reads typed
    op          the op base class, its declarations and the registry; parsing
    graph, bridges, topics, parameters, tf, robots, services, markers, motion, actions,
    interfaces, recording, playback
                the ops, by area, each with its result type and examples (adding an op: a
                class in one of these, and a handler returning its result)
    replies     the Reply and error replies

Everything is importable from ``protocol.commands`` itself.
"""

from __future__ import annotations

from protocol.commands.errors import *  # noqa: F403
from protocol.commands.errors import __all__ as _errors
from protocol.commands.wire import *  # noqa: F403
from protocol.commands.wire import __all__ as _wire
from protocol.commands.values import *  # noqa: F403
from protocol.commands.values import __all__ as _values
from protocol.commands.types import *  # noqa: F403
from protocol.commands.types import __all__ as _types
from protocol.commands.results import *  # noqa: F403
from protocol.commands.results import __all__ as _results
from protocol.commands.op import *  # noqa: F403
from protocol.commands.op import __all__ as _op
from protocol.commands.graph import *  # noqa: F403
from protocol.commands.graph import __all__ as _graph
from protocol.commands.bridges import *  # noqa: F403
from protocol.commands.bridges import __all__ as _bridges
from protocol.commands.topics import *  # noqa: F403
from protocol.commands.topics import __all__ as _topics
from protocol.commands.parameters import *  # noqa: F403
from protocol.commands.parameters import __all__ as _parameters
from protocol.commands.tf import *  # noqa: F403
from protocol.commands.tf import __all__ as _tf
from protocol.commands.robots import *  # noqa: F403
from protocol.commands.robots import __all__ as _robots
from protocol.commands.services import *  # noqa: F403
from protocol.commands.markers import *  # noqa: F403
from protocol.commands.markers import __all__ as _markers
from protocol.commands.motion import *  # noqa: F403
from protocol.commands.motion import __all__ as _motion
from protocol.commands.services import __all__ as _services
from protocol.commands.actions import *  # noqa: F403
from protocol.commands.actions import __all__ as _actions
from protocol.commands.interfaces import *  # noqa: F403
from protocol.commands.interfaces import __all__ as _interfaces
from protocol.commands.recording import *  # noqa: F403
from protocol.commands.recording import __all__ as _recording
from protocol.commands.playback import *  # noqa: F403
from protocol.commands.playback import __all__ as _playback
from protocol.commands.replies import *  # noqa: F403
from protocol.commands.replies import __all__ as _replies

__all__ = [*_errors, *_wire, *_values, *_types, *_results, *_op, *_graph, *_bridges, *_topics,
           *_parameters, *_tf, *_robots, *_services, *_markers, *_motion, *_actions, *_interfaces,
           *_recording, *_playback, *_replies]

bridge_kinds()  # noqa: F405 - a create op without its remove op fails here, at import
