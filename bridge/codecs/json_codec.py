"""The fallback codec: any installed message type as its full JSON in a STRING body."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from bridge.codecs.base import KEY_FORMAT, Body, TypeCodec, json_body, parse_json_text, string_text
from bridge.codecs.generic import dict_to_message, message_to_dict

__all__ = ["GenericJsonCodec"]


@dataclass(frozen=True)
class GenericJsonCodec(TypeCodec):
    """``pkg/msg/Type`` <-> STRING holding `message_to_dict` as JSON; the value is that dict.

    Back, missing fields keep their defaults; unknown fields and wrong types raise
    `CodecError` naming the field path.
    """

    def _to_value(self, msg: Any) -> Any:
        return message_to_dict(msg)

    def _to_igtl(self, msg: Any) -> tuple[Body, dict[str, str]]:
        return json_body(message_to_dict(msg)), {KEY_FORMAT: "json"}

    def _from_igtl(self, body: Body, metadata: dict[str, str]) -> Any:
        return dict_to_message(self.message_class,
                               parse_json_text(string_text(body, self.ros_type)))

    def _from_value(self, value: Any) -> Any:
        return dict_to_message(self.message_class, value)
