"""The one pipeline (issue 29): one right-hand-side call written once over a mode's packed arrays.

``pack`` lays a mode out as flat arrays once (Python); ``pipeline`` is the call (numba, or the same source
interpreted under ``NUMBA_DISABLE_JIT=1``): robot terms, contact kinematics, chains, friction and limit rows,
the controller (by address or the compiled task PD law), torque drives, the KKT assembly and solve, the rates
and the event values. Nothing here is probed; every mode the pack accepts runs on it
(:class:`contactdyn.model.paths.LivePipelines`).
"""
