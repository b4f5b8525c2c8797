"""The library's front door: each command of the CLI as one function (re-exported lazily by :mod:`wmrid`).

Above every other layer but the CLI: it reads logs (:mod:`wmrid.io`), runs estimators (:mod:`wmrid.estimators`),
simulates (:mod:`wmrid.sim`), monitors (:mod:`wmrid.monitoring`) and reports (:mod:`wmrid.reporting`).  Library errors
name options by their Python names (``friction='wheel+caster'``); the CLI shows the flags instead.
"""
