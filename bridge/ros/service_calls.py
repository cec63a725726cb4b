"""Calling a ROS service from the asyncio loop without blocking it or the executor: the
service and parameter capabilities' shared client machinery."""

from __future__ import annotations

import asyncio
from typing import Any, Optional

from rclpy.client import Client
from rclpy.exceptions import InvalidHandle
from rclpy.task import Future as RosFuture

from bridge.core.hub import Hub
from protocol.commands import CommandFailedError, ErrorCode

__all__ = ["call_ros_service", "wait_until_ready"]

# How often an async wait re-checks that a service server has been discovered.
_READY_POLL_S = 0.05
# How long a request that must not be sent twice waits after its server is first seen:
# this side matching the server does not mean the server has matched this side yet, and a
# request that reaches its (volatile) reader before then is dropped, never resent.
FRESH_MATCH_SETTLE_S = 0.5


async def wait_until_ready(client: Client, wait_s: float) -> bool:
    """True once `client` sees a server, False after `wait_s` (polled on the loop: the
    check is one cheap rcl call, and no thread blocks)."""
    loop = asyncio.get_running_loop()
    deadline = loop.time() + wait_s
    while not client.service_is_ready():
        if loop.time() >= deadline:
            return False
        await asyncio.sleep(_READY_POLL_S)
    return True


async def call_ros_service(hub: Hub, client: Client, request: Any, *, timeout: float,
                           ready_wait: float, what: str, field: str,
                           resend_every: Optional[float] = None) -> Any:
    """Call a ROS service from the asyncio loop and return its response.

    Waits up to ``min(timeout, ready_wait)`` for the server (else UNAVAILABLE), then for the
    response until ``timeout`` has passed in all (else TIMEOUT). The errors name ``field``.

    ``resend_every`` is for idempotent requests only (reads): the request is sent again at
    that interval until an answer comes, and the first answer wins. A server seen in the
    graph may not have matched this client's request writer or response reader yet (Fast
    DDS waits 100 ms for the latter, then drops the response: ros2/rmw_fastrtps#392), so on
    a busy machine the first request or its answer can be lost outright. A request sent
    once only (no ``resend_every``) to a server just found (not ready at the first look)
    waits `FRESH_MATCH_SETTLE_S` more, so that the server's side of the match can happen.
    """
    loop = asyncio.get_running_loop()
    start = loop.time()
    deadline = start + timeout
    outcome: asyncio.Future[Any] = loop.create_future()
    sent: list[RosFuture] = []

    def send() -> None:
        ros_future = client.call_async(request)
        sent.append(ros_future)
        # Runs in the executor thread (or at once if already done): hand off only.
        ros_future.add_done_callback(
            lambda done: hub.call_soon(_transfer, done, outcome))

    try:
        found_just_now = not client.service_is_ready()
        if not await wait_until_ready(client, min(timeout, ready_wait)):
            raise CommandFailedError(field, f"{what} to be available",
                                     f"no server after {min(timeout, ready_wait):g} s",
                                     code=ErrorCode.UNAVAILABLE)
        if found_just_now and resend_every is None:
            await asyncio.sleep(min(FRESH_MATCH_SETTLE_S, max(0.0, deadline - loop.time())))
        send()
        while True:
            left = deadline - loop.time()
            wait = left if resend_every is None else min(left, resend_every)
            done, _ = await asyncio.wait((outcome,), timeout=max(0.0, wait))
            if done:
                return outcome.result()
            if loop.time() >= deadline:
                raise CommandFailedError(field, f"a response from {what} within {timeout:g} s",
                                         "no response", code=ErrorCode.TIMEOUT)
            send()
    except InvalidHandle:  # the bridge was removed meanwhile
        raise CommandFailedError(field, f"{what} to be available", "a removed client",
                                 code=ErrorCode.UNAVAILABLE) from None
    finally:
        for ros_future in sent:
            if not ros_future.done():
                client.remove_pending_request(ros_future)


def _transfer(ros_future: RosFuture, outcome: asyncio.Future[Any]) -> None:
    if outcome.done():  # timed out meanwhile
        return
    if ros_future.cancelled():
        outcome.set_exception(CommandFailedError("service", "a response", "a cancelled call",
                                                 code=ErrorCode.ROS_ERROR))
    elif ros_future.exception() is not None:
        outcome.set_exception(CommandFailedError(
            "service", "a response", str(ros_future.exception()),
            code=ErrorCode.ROS_ERROR))
    else:
        outcome.set_result(ros_future.result())
