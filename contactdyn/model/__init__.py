"""The model: contact chains and their forces, friction, joint limits, the constraint rows at impulse level,
impact, task phases, the state layout and the system a scene builds; `pipeline/` is the right-hand side, one call
compiled or interpreted; `evaluation` holds what it answers at an instant."""
