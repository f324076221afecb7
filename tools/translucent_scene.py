"""The translucency accuracy scene's command-line arguments, shared by the two reference
renderers (translucent_reference.py: Mitsuba; translucent_light_tracer.py: numpy): a ball of a
homogeneous medium at the origin (or, Mitsuba only, a closed triangle mesh about it: `--mesh`),
a perspective camera looking at it, one directional light (or a point light back along it).
"""

import argparse


def numbers(count, word=None):
    """An argparse type: `count` comma-separated numbers (`word` names the count)."""
    def parse(text):
        try:
            values = [float(v) for v in text.split(",")]
        except ValueError:
            values = []
        if len(values) != count:
            raise argparse.ArgumentTypeError(f"{text!r} is not {word or count} comma-separated numbers")
        return values
    return parse


triple = numbers(3, "three")


def add_scene_arguments(parser):
    """The medium, the ball, the camera, the light and the picture's size."""
    parser.add_argument("--sigma-a", type=triple, required=True, help="absorption per mm, r,g,b")
    parser.add_argument("--sigma-s", type=triple, required=True, help="scattering per mm (g = 0), r,g,b")
    shape = parser.add_mutually_exclusive_group(required=True)
    shape.add_argument("--radius", type=float, help="ball radius, metres")
    shape.add_argument("--mesh", help="a closed triangle mesh in place of the ball (OBJ, metres; "
                                      "translucent_reference.py only)")
    parser.add_argument("--eye", type=triple, required=True, help="camera position (looks at the origin, +Y up)")
    parser.add_argument("--light", type=triple, required=True, help="direction the light travels")
    parser.add_argument("--fov", type=float, default=45.0, help="vertical field of view, degrees")
    parser.add_argument("--size", type=int, default=96, help="image width = height, pixels")
    parser.add_argument("--out", required=True, help="EXR to write")
    parser.add_argument("--point-light", type=float, default=None, metavar="DISTANCE",
                        help="a point light this far (metres) from the origin, back along --light, "
                             "of irradiance 1 across its rays at the origin, instead of the "
                             "directional light")


def point_light_position(args, scale=1.0):
    """`--point-light`'s position (in metres times `scale`): back along `--light` from the
    origin."""
    length = sum(v * v for v in args.light) ** 0.5
    return [-scale * args.point_light * v / length for v in args.light]
