"""``coral-run watch``: a mission's state in a browser, live from its log or replayed.

`state` is the pure model (a log's rows up to time t to the snapshot), `source` reads a
controller log's new rows cheaply while its writer goes on, `server` serves the page, the
snapshots and a live stream, and `main` is the command. The page and the server only read
the log: nothing here can act on the mission (operator actions come later, with their own
access right).

Import rule: this package imports `runtime.eventlog`, `coral_lang` and the standard library
(and aiohttp), never the engine or a simulator, so watching a log needs neither.
"""
