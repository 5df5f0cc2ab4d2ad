"""One browser tab: ``LabSession`` composes small parts with explicit interfaces (the
tab's worker, the class-token gate, saved experiments, controls and typed values, the
analysis view, streaming on the shared frame clock, analysis turns).  Every part sets
its state in ``__init__`` and no other module writes into it.  Imports ``app.panels``
and ``app.infra``, never ``app.commands`` or the roots."""
