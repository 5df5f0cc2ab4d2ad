"""Headless commands: run, list, save, reproduce, and the benches (speed, load,
browser).  They import ``app.infra``, ``app.panels`` and the lab's modules, never
``app.tab`` or the roots (a bench that needs a tab starts a lab process)."""
