"""The live view: every stream of a run served over Foxglove's WebSocket protocol while it is recorded
(docs/live-view.md).

`options.py` parses `--live [HOST:]PORT`; `tap.py` is the side door the recorder offers each message to (beside its
queue, never in front of it); `decimate.py` thins high-rate streams for display; `server.py` runs the foxglove-sdk
server and its publishing thread; `control.py` is the abort service and its token. `session.py` ties one server to
the runs of a command. The recording never waits for a client: a slow, stalled or vanished client costs the
recorder one append per message, and whatever the live side cannot keep up with is dropped there, counted.
"""
