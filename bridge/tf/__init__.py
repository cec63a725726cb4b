"""The daemon's tf2 core, plain Python (no rclpy): a buffer of transforms and lookups on it.

- `TfBuffer` (buffer.py): fed by the daemon's /tf and /tf_static subscriptions, answers
  tf2-style lookups with tf2's error wording and codes. Its samples live in a store:
  store.py (pure Python, the reference) or _compiled_store.pyx (the same in C through
  Cython, used where it was built; tests hold the two to the same bits).
- `LookupRegistry` (lookups.py): the lookups clients registered; tells the daemon which
  results changed after each batch, with per-lookup rate caps.
- math.py: quaternion / rigid-transform algebra on float tuples; errors.py: the error tree.
"""

from bridge.tf.buffer import FrameInfo, StampedTransform, TfBuffer
from bridge.tf.errors import (
    ConnectivityError,
    ExtrapolationError,
    InvalidArgumentError,
    RejectedTransformsError,
    TfError,
    TfErrorCode,
    TfLookupError,
)
from bridge.tf.lookups import LookupKey, LookupRegistry, LookupResult

__all__ = [
    "TfBuffer",
    "StampedTransform",
    "FrameInfo",
    "LookupRegistry",
    "LookupKey",
    "LookupResult",
    "TfError",
    "TfErrorCode",
    "TfLookupError",
    "ConnectivityError",
    "ExtrapolationError",
    "InvalidArgumentError",
    "RejectedTransformsError",
]
