"""The robot: the explorer served step by step to a real or simulated hand, as JSON lines
(``explore --stdio``) or as ROS 2 nodes (``explore --ros``, ``robot --ros``); one session
answers both.

It uses attention and the experiments' seeds; the report knows nothing of it.
"""
