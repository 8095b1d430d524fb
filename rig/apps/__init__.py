"""What users run: the ``rig`` command, replays of real flights, identification from a
log, and campaigns (their bundled files beside them). On top of everything; nothing in
the rig imports them.
"""
