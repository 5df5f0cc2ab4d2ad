"""The AMB estimation lab in a browser and on the command line, laid out by role.

Lowest first: ``infra`` (store, access, traffic, layout, and the one place that
touches viser's private names), ``panels`` (what a tab shows, each built with the
callbacks and data it needs), then side by side ``tab`` (one browser tab: the
parts a ``LabSession`` is made of) and ``commands`` (headless commands: run,
reproduce, benches), and the roots on top: ``cli`` (argument parsing and
dispatch), ``server`` (the classroom server) and ``hall`` (several servers
behind HAProxy).  A module imports only from its own layer or lower ones, and
nothing imports in a circle (``tests/test_layers.py``).
"""
