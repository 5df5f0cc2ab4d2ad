"""The AMB estimation lab's modules, laid out as the block diagram.

Lowest first: ``parameters``, ``formatting`` (numbers as a student reads
them), ``claims``, ``analysis`` and ``recordings`` (foundation); ``plants``;
``estimators`` and ``controllers``; ``loops``; ``scenes`` and ``exercises``
on top.  A module imports only from its own layer or lower ones (checked by
``tests/test_layers.py``).
"""
