"""A crowd running a shot: the :class:`~.crowd.Crowd` facade and its frame, the show's
runner, snapshots, and the recorder with the recording every writer reads. The top
of core.
"""
