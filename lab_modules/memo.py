"""Pay once: results of a computation on parameter values remembered per setting of the values it
read.  ``ReadValues`` notes the names a computation reads (what it depends on, found by running
it); ``Memo`` keeps results per setting of those names, bounded; ``remembered`` is the decorator
for a function of the values.  A slider a computation never reads does not make it run again."""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Callable, Hashable
from typing import TypeVar

Result = TypeVar("Result")
_MISSING = object()                 # a value a computation asked for but the values do not hold


class ReadValues(dict):
    """Parameter values that note the names read from them (``read``): what a computation
    depends on, found by running it.  Reading every value (iterating, copying, comparing) marks
    them all."""

    def __init__(self, values: dict):
        super().__init__(values.raw() if isinstance(values, ReadValues) else values)
        self.read: set = set()

    def raw(self) -> dict:
        """The values, without marking them read."""
        return dict(super().items())

    def _read_all(self) -> None:
        self.read.update(super().keys())

    def __getitem__(self, name):
        self.read.add(name)
        return super().__getitem__(name)

    def get(self, name, default=None):
        self.read.add(name)
        return super().get(name, default)

    def __contains__(self, name) -> bool:
        self.read.add(name)
        return super().__contains__(name)

    def __iter__(self):
        self._read_all()
        return super().__iter__()

    def keys(self):
        self._read_all()
        return super().keys()

    def values(self):
        self._read_all()
        return super().values()

    def items(self):
        self._read_all()
        return super().items()

    def copy(self) -> dict:
        self._read_all()
        return self.raw()

    def __eq__(self, other) -> bool:
        self._read_all()
        return super().__eq__(other)

    def __ne__(self, other) -> bool:
        return not self == other

    __hash__ = None


class Memo:
    """Results of a computation on parameter values, each remembered per setting of the values it
    read (``ReadValues``; a slider it never reads does not make it run again) and of its other
    arguments (``key``), at most ``size`` of them (the least recently used go first).  A setting
    whose read values cannot be hashed (an uploaded recording) is not remembered.  Thread-safe;
    two threads asking for the same new setting at once may both compute it."""

    def __init__(self, size: int = 64):
        self.size = size
        self.lock = threading.Lock()
        self.entries: OrderedDict = OrderedDict()        # (key, names, their values) -> result
        self.read_sets: dict[Hashable, list[tuple]] = {}  # key -> the name tuples it has read, newest first

    def find(self, key: Hashable, values: dict) -> tuple[object, tuple] | None:
        """(the result remembered for ``values``, the names it read), or None."""
        raw = values.raw() if isinstance(values, ReadValues) else values
        with self.lock:
            for names in self.read_sets.get(key, ()):
                setting = _setting(raw, names)
                entry = self.entries.get((key, names, setting)) if setting is not None else None
                if entry is not None:
                    self.entries.move_to_end((key, names, setting))
                    return entry[0], names
        return None

    def keep(self, key: Hashable, values: dict, read: set, result) -> None:
        """Remember ``result``, computed from ``values`` reading ``read``."""
        raw = values.raw() if isinstance(values, ReadValues) else values
        names = tuple(sorted(read, key=str))
        setting = _setting(raw, names)
        if setting is None:
            return
        with self.lock:
            known = self.read_sets.setdefault(key, [])
            if names in known:
                known.remove(names)
            known.insert(0, names)
            self.entries[(key, names, setting)] = (result,)
            self.entries.move_to_end((key, names, setting))
            while len(self.entries) > self.size:
                (old_key, old_names, _), _ = self.entries.popitem(last=False)
                if not any(k == old_key and n == old_names for k, n, _ in self.entries):
                    self.read_sets[old_key].remove(old_names)

    def call(self, key: Hashable, values: dict, compute: Callable[[dict], Result]) -> Result:
        """``compute(values)``, or its remembered result for this setting.  When ``values`` are
        themselves being read for an outer memo, what this computation read is marked there."""
        found = self.find(key, values)
        if found is None:
            tracked = ReadValues(values)
            result, names = compute(tracked), tracked.read
            self.keep(key, values, names, result)
        else:
            result, names = found
        if isinstance(values, ReadValues):
            values.read.update(names)
        return result


def _setting(values: dict, names: tuple) -> tuple | None:
    """The values of ``names`` (missing ones as a marker), or None if one cannot be hashed."""
    setting = tuple(values.get(name, _MISSING) for name in names)
    try:
        hash(setting)
    except TypeError:
        return None
    return setting


def remembered(size: int = 64) -> Callable:
    """Decorator: ``function(values, *arguments)`` (hashable arguments) computed once per setting of
    the parameter values it reads and of its arguments (``Memo``)."""
    def decorate(function: Callable[..., Result]) -> Callable[..., Result]:
        memo = Memo(size)

        def wrapper(values: dict, *arguments) -> Result:
            return memo.call(arguments, values, lambda read: function(read, *arguments))
        wrapper.__doc__, wrapper.__name__, wrapper.__wrapped__ = function.__doc__, function.__name__, function
        wrapper.memo = memo
        return wrapper
    return decorate
