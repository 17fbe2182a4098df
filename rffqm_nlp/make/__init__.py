"""From design to object: cut files in millimetres, thick panels that fold, and a lock at
the designed shape (docs/make.md).

:func:`make` takes a design result and the options of :data:`MAKE_KEYS` (a size, a
thickness, a process and its parameters) and returns :class:`Made`, which writes the
folder: the cut and score files and the fold angles (:mod:`.cut_files` on the sheet of
:mod:`.sheet`), the assembly sheet (:mod:`.assembly`), the thick panels (:mod:`.solids`,
tapered after Tachi: :mod:`rffqm_nlp.contact.thick`) and the lock (:mod:`.lock`, its
printable parts in :mod:`.parts`). The options are checked in :mod:`.options`.

``rq.make`` is this package and is called as the function :func:`make` too
(``rq.make(result, width="300mm")``): the package and the function share the name, and
importing the package makes it the package's attribute of ``rffqm_nlp``, so the package
itself is callable.
"""

from __future__ import annotations

import sys
import types

from .lock import Stop, Tie, crease_stops, lock_ties, tie_candidates
from .options import MAKE_KEYS, PAPERS, PROCESSES, MakeOptions, length, make_options
from .run import Made, make
from .sheet import Sheet, perforation


class _CallableModule(types.ModuleType):
    """A module that is called as :func:`make`."""

    def __call__(self, *args, **kwargs) -> Made:
        return make(*args, **kwargs)


sys.modules[__name__].__class__ = _CallableModule

__all__ = ["MAKE_KEYS", "PAPERS", "PROCESSES", "Made", "MakeOptions",
           "Sheet", "Stop", "Tie", "crease_stops", "length", "lock_ties",
           "make", "make_options", "perforation", "tie_candidates"]
