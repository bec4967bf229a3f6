"""``reachd``: the receiver daemon, the single owner of the hardware.

It runs schedules from a queue and on timers through the run layer
(:class:`~reach_receiver.run.session.RunSession`), answers a control socket, keeps
systemd informed (readiness, status, watchdog), and recovers from its own crashes and
power cuts. The command line (``reachd``) is in :mod:`reach_receiver.cli`.
"""
