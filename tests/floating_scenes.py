"""A scene shared by the floating-base tests of tests/multibody and tests/diagrams."""

#: a free box thrown up, pitched and spinning: every coordinate of its base moves (in the air
#: for the whole of the tests)
TOSSED = {
    "name": "tossed_box",
    "models": [{"file": "package://drake_abs/models/box_floating.sdf"}],
    "contacts": [{"body": "box", "geometry": "collision", "friction": 0.5}],
    "initial_state": {
        "q": [0.1, -0.2, 0.5, 0.4, -0.3, 0.2],
        "v": [0.5, 0.1, -0.2, 1.0, 2.0, -1.0],
    },
}
