"""The AMB estimation lab: browser server, per-tab sessions and headless CLI."""
