"""What every other part of the app stands on: the experiment store (sqlite3), access
checks (host, port, token, Origin), the traffic of each connection, the dock layout,
and ``viser_internals``, the one module that touches viser's private names.  Imports
nothing else of the app."""
