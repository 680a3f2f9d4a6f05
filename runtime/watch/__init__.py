"""A mission's state in a browser: live from a running ``coral-run``, or from its log.

`state` is the pure model (a log's rows up to time t to the snapshot), `source` reads a
controller log's new rows cheaply while its writer goes on, `feed` keeps a running
mission's state from its own event log (a listener, no polling), `server` serves the page,
the snapshots, a live stream and the operator's ``POST /operate``, `live` embeds that
server in a running controller with the operate right (``coral-run MISSION --watch``), and
`main` is ``coral-run watch LOG`` (view only).

Import rule: this package imports `runtime.eventlog`, `runtime.operator`, `coral_lang`
and the standard library (and aiohttp), never the engine or a simulator, so watching a
log needs neither; a running controller hands the live server its ``operate`` coroutine.
"""
