"""The ``[obstacle]`` table of a case file: the rigid obstacle's shape and its indentation steps or rigid
motions (``problem.case``; a value that is not what its key asks for is an InputError naming the key)."""

import math
from dataclasses import dataclass

from fenics_contact.problem.case_values import (
    Bad,
    Source,
    Table,
    read_direction,
    read_number,
    read_point,
    read_points,
    read_string,
)
from fenics_contact.problem.obstacles import Circle, Obstacle, Plane, Sphere

__all__ = ["ObstacleSpec", "read_obstacle"]


@dataclass(frozen=True, slots=True)
class ObstacleSpec:
    """The rigid obstacle and its indentation steps (depths along ``direction``)."""

    shape: str = "wall"
    point: tuple[float, ...] | None = None
    normal: tuple[float, ...] | None = None
    centre: tuple[float, ...] | None = None
    radius: float | None = None
    depths: tuple[float, ...] = ()
    direction: tuple[float, ...] | None = None
    steps: bool = False  #: ``indentation`` was a list: load steps, a force–indentation curve
    motions: tuple[tuple[float, ...], ...] = ()  #: rigid displacements, one per load step (a sliding path)

    def base(self) -> Obstacle | None:
        """The obstacle where the case places it (None: the wall flush with Gamma_C)."""
        if self.shape == "plane":
            return Plane(self.point, self.normal)
        if self.shape == "circle":
            return Circle(self.centre, self.radius)
        if self.shape == "sphere":
            return Sphere(self.centre, self.radius)
        return None

    def at(self, depth: float) -> Obstacle:
        return self.base().indented(depth, self.direction)

    def final(self) -> Obstacle | None:
        """The obstacle at the last indentation depth or motion (the one the run solves for)."""
        if self.motions:
            return self.base().translated(self.motions[-1])
        return self.at(self.depths[-1]) if self.depths else self.base()

    def echo(self) -> dict:
        out = {"shape": self.shape}
        if self.shape == "plane":
            out |= {"point": list(self.point), "normal": list(self.normal)}
        elif self.shape in ("circle", "sphere"):
            out |= {"centre": list(self.centre), "radius": self.radius}
        if self.depths:
            out |= {
                "indentation": list(self.depths) if self.steps else self.depths[0],
                "direction": list(self.direction),
            }
        if self.motions:
            out["motion"] = [list(m) for m in self.motions]
        return out


def read_obstacle(source: Source, data) -> ObstacleSpec:
    """The obstacle of the ``[obstacle]`` table ``data`` (default: the wall flush with Gamma_C)."""
    t = Table(source, "obstacle", data or {})
    shape = t.get("shape", read_string(("wall", "plane", "circle", "sphere")), "wall")
    point = normal = centre = radius = None
    if shape == "plane":
        point = t.get("point", read_point, required=True)
        normal = t.get("normal", read_direction, required=True)
    elif shape in ("circle", "sphere"):
        centre = t.get("centre", read_point, required=True)
        radius = t.get("radius", read_number(positive=True), required=True)
    indentation = t.raw("indentation")
    direction = t.get("direction", read_direction)
    motions = t.get("motion", read_points, ())
    t.finish(f' for shape = "{shape}"')
    if motions and (indentation is not None or shape == "wall"):
        raise source.error(
            "obstacle.motion moves a plane, a circle or a sphere (not the default wall) and replaces "
            "obstacle.indentation: "
            "give one of the two"
        )
    steps = isinstance(indentation, list)
    if indentation is None:
        depths = ()
    else:
        values = indentation if steps else [indentation]
        if steps and not values:
            raise source.error("obstacle.indentation is an empty list: give the depths of the load steps")
        try:
            depths = tuple(read_number()(v) for v in values)
        except Bad as bad:
            raise source.error(f"obstacle.indentation {bad}") from None
    if depths and shape == "wall":
        raise source.error(
            'obstacle.indentation moves a plane, a circle or a sphere: give shape = "plane", "circle" or "sphere" '
            "(the default wall is flush with Gamma_C)"
        )
    if direction is not None and not depths:
        raise source.error("obstacle.direction is the direction of obstacle.indentation, which is not given")
    if depths and direction is None:
        if shape != "plane":
            raise source.error(
                f"obstacle.direction is required with obstacle.indentation for a {shape} (the direction "
                f"it moves in, e.g. {'[0, -1]' if shape == 'circle' else '[0, 0, -1]'})"
            )
        direction = normal  # along its outward normal: into the body
    if direction is not None:
        length = math.hypot(*direction)
        direction = tuple(v / length for v in direction)
    return ObstacleSpec(shape, point, normal, centre, radius, depths, direction, steps, motions)
