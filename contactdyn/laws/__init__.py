"""The laws: stage laws, friction laws, drive kinds, controllers and reference profiles.

A law is a class registered by name that declares its parameters once (:class:`Param`); the scene
reader, the key reference and the model use the declaration. The laws import nothing of the model.
Your own law imports its base from here (``from contactdyn.laws import StageLaw, register_stage_law``)."""

from importlib import import_module

#: public name -> the module that defines it (imported on first use: no import cycle, a light start)
_PUBLIC = {
    **dict.fromkeys(("Param",), ".params"),
    **dict.fromkeys(("StageLaw", "register_stage_law", "STAGE_LAWS"), ".stage_laws"),
    **dict.fromkeys(("FrictionLaw", "FrictionSpec", "register_friction_law", "FRICTION_LAWS"), ".friction_laws"),
    **dict.fromkeys(("DriveKind", "register_drive_kind", "DRIVE_KINDS"), ".drive_kinds"),
    **dict.fromkeys(("Controller", "ControlInput", "register", "CONTROLLERS"), ".controllers"),
}
__all__ = list(_PUBLIC)


def __getattr__(name: str):
    if name not in _PUBLIC:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = globals()[name] = getattr(import_module(_PUBLIC[name], __name__), name)
    return value
