"""COMMANDs the daemon sends to a client (a ROS call to serve, a goal to run or to decide on,
a cancel) and the client's RTS_COMMAND answers to them.

One correlator for the daemon: its command ids are unique across everything it sends, so a
client that serves a service and an action never has one's answer taken for the other's.
An awaited answer ends exactly once: the answer came (`on_answer(text)`), or none will
(`on_silence(timed_out)`: its time ran out, or what it was `about` was withdrawn). Loop
thread only.
"""

from __future__ import annotations

import asyncio
import itertools
from dataclasses import dataclass
from typing import Callable, Mapping, Optional

from bridge.core.hub import Hub, Replier
from protocol.commands import Op
from protocol.messages import Command, Message, RtsCommand

__all__ = ["ClientReplies"]


@dataclass(eq=False)
class _Awaited:
    about: object  # what the command concerns (a served service or action)
    on_answer: Callable[[str], None]
    on_silence: Callable[[bool], None]
    timer: Optional[asyncio.TimerHandle] = None


class ClientReplies:
    """Sends COMMANDs to clients and hands each awaited RTS_COMMAND to its waiter."""

    def __init__(self, hub: Hub) -> None:
        self._ids = itertools.count(1)
        self._awaited: dict[tuple[Replier, int], _Awaited] = {}
        hub.add_reply_listener(self._on_reply)

    def tell(self, client: Replier, device: str, command: Op,
             metadata: Mapping[str, str]) -> int:
        """Send ``command`` without awaiting an answer; its command id. Raises the
        `CommandError` of an unencodable command before sending anything."""
        command_id = next(self._ids)
        client.send_message(Message(
            device_name=device,
            body=Command(command_id=command_id, name=command.op, text=command.to_json()),
            metadata=dict(metadata)))
        return command_id

    def ask(self, client: Replier, device: str, command: Op, metadata: Mapping[str, str], *,
            timeout: float, about: object, on_answer: Callable[[str], None],
            on_silence: Callable[[bool], None]) -> None:
        """Send ``command`` and await the client's answer for ``timeout`` seconds (see the
        module). Raises the `CommandError` of an unencodable command before sending."""
        text = command.to_json()
        command_id = next(self._ids)
        awaited = _Awaited(about, on_answer, on_silence)
        key = (client, command_id)
        awaited.timer = asyncio.get_running_loop().call_later(timeout, self._expire, key)
        self._awaited[key] = awaited
        client.send_message(Message(
            device_name=device, body=Command(command_id=command_id, name=command.op, text=text),
            metadata=dict(metadata)))

    def withdraw(self, about: object) -> None:
        """No answer about ``about`` is awaited any more: each waiter hears silence."""
        for key, awaited in list(self._awaited.items()):
            if awaited.about is about:
                del self._awaited[key]
                self._end(awaited).on_silence(False)

    def _on_reply(self, message: Message, client: Replier) -> None:
        body = message.body
        if not isinstance(body, RtsCommand):
            return
        awaited = self._awaited.pop((client, body.command_id), None)
        if awaited is not None:  # else not awaited, or it came after its time
            self._end(awaited).on_answer(body.text)

    def _expire(self, key: tuple[Replier, int]) -> None:
        awaited = self._awaited.pop(key, None)
        if awaited is not None:
            awaited.timer = None
            awaited.on_silence(True)

    @staticmethod
    def _end(awaited: _Awaited) -> _Awaited:
        if awaited.timer is not None:
            awaited.timer.cancel()
            awaited.timer = None
        return awaited
