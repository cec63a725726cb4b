"""Topic bridges (`bridge.topics.capability`): `create_subscriber`, `remove_subscriber`,
`create_publisher`, `remove_publisher`, `publish` and `get_last_message`."""

from bridge.topics.capability import TopicBridges

__all__ = ["TopicBridges"]
