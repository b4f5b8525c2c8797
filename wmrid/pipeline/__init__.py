"""The identification workflow: what runs on a log, in which order, as straight-line code over typed records.

:mod:`wmrid.pipeline.identify` is the route of ``wmrid identify`` after the log is read: the options checked, the
efforts' timing decided (:mod:`wmrid.pipeline.timing`), the observer's passes the log needs
(:func:`wmrid.estimators.observer.observe.observe`, once per friction model and timing), the friction model chosen
(:mod:`wmrid.pipeline.friction`), the widenings, the closed-loop check.  The estimators below it decide nothing about
a log and never re-enter the workflow.
"""
