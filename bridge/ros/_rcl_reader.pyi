"""Types of the compiled rcl reader (_rcl_reader.pyx). Keep in step with the .pyx (and its
INTERFACE)."""

from collections.abc import Collection
from typing import Any

from typing_extensions import Self, disjoint_base

INTERFACE: int

class ReaderError(RuntimeError): ...

@disjoint_base
class RawReader:
    # rclpy's _rclpy handles (Context, Subscription, GuardCondition), of which the reader
    # reads `pointer`: untyped C++ objects (rclpy's ContextHandle protocol omits `pointer`).
    # __cinit__ takes the arguments: at run time they are __new__'s.
    def __new__(cls, context: Any, subscriptions: Collection[Any], wake: Any) -> Self: ...
    def take(self, timeout_s: float) -> tuple[int, memoryview] | None: ...
    def set_subscriptions(self, subscriptions: Collection[Any]) -> None: ...
    def take_more(self, index: int, max_count: int, max_bytes: int) -> list[bytes]: ...
    def close(self) -> None: ...
