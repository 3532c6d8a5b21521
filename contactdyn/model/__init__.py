"""The model: contact chains and their forces, friction, joint limits, the constraint rows and the KKT
solve, impact, task phases, the state layout and the system a scene builds; `dynamics.evaluate` is one
right-hand side, readable."""
