"""The daemon's machinery, which every capability uses: clients in, commands dispatched,
frames out, and the policy that judges them. It imports no capability: the daemon hands
each (bridge/<capability>/) to the dispatcher as a `dispatch.Capability`, its ops' handlers.
It reaches ROS only through bridge/ros/; host workarounds live in bridge/platform/.

- server.py: the OpenIGTLink TCP server: accepts clients (TLS, --allow, --max-clients).
- session.py: one connected client: decodes its bytes, writes its frames.
- hub.py: the daemon-wide switch between ROS-side bridges and connected clients.
- outbox.py: a client's bounded send buffer (newest value per streamed device).
- dispatch.py: a client's COMMAND -> the op's handler -> an RTS_COMMAND reply.
- security.py: the security policy: who may connect and what a client may do.
- content_guards.py: the policy inside content (messages, results) that names frames or
  parameters, as each op declares it; handed to handlers by the dispatcher.
- knock.py: a reset delivered to a plain client whose link died, once the link is back.
- heavy.py: heavy work (decoding, encoding) off the event loop, one lane per client.
- stream_health.py: tells clients when a stream goes stale and when it comes back.
- logging_limits.py: a rate-limited logger for warnings a peer can repeat at will.
- shutdown.py: a stop that always ends, whatever ROS's teardown does.
- client_replies.py: the daemon's COMMANDs to a client paired with the client's answers.
"""
