#!/usr/bin/env python3
"""Writes fast camera loops for the shared scenes (issue 22 item 5) to tests/data/camera-loops/.

The shared loops move at most ~0.8 degrees and ~0.3% of the scene per frame. These move the
way a user in a hurry does, at 30 frames per second, starting from each shared loop's first
view (a view the scene's author chose, inside the scene):

  <scene>-turn90.json  a turn of 90 degrees to the left in 2 s (60 frames, 1.5 degrees per
                       frame) and back in 2 s: 120 frames, closed.
  <scene>-walk.json    a walk towards the first view's target, 40% of the way there in 2 s
                       (the target is what the author looked at, so the path stays in the
                       scene), with a 30-degree look to the right on the way, and back: 120
                       frames, closed. Pavilion: 8.6 m in 2 s; living room and kitchen: 1.2 m.

  pavilion-door.json   a walk through the pavilion's entrance, the gap between a glass wall
                       and the marble wall under the roof: from the terrace beside the pool
                       (x = -4.5, z = 3) into the room beyond (x = 3.5), 8 m in 3 s looking
                       ahead, and back (180 frames). The walls hide most of the room until the
                       camera is through, then the sides open up. The path (clear of the
                       chairs and the pool) was chosen from renders at eye level along it.

Same JSON format as the shared loops. Deterministic: run it again and the files do not change.
Usage: bench/make_camera_loops.py [SCENES_DIR] [OUT_DIR]
"""
import json
import math
import os
import sys

SCENES = ("pavilion", "living-room", "kitchen")
FPS = 30


def sub(a, b):
    return [a[i] - b[i] for i in range(3)]


def add(a, b):
    return [a[i] + b[i] for i in range(3)]


def scale(a, s):
    return [x * s for x in a]


def rotate_y(v, angle):
    """Rotates v about the +Y axis (the scenes' up) by angle radians (positive: to the left)."""
    c, s = math.cos(angle), math.sin(angle)
    return [c * v[0] + s * v[2], v[1], -s * v[0] + c * v[2]]


def frame(eye, target):
    return {"eye": [round(x, 6) for x in eye], "target": [round(x, 6) for x in target], "up": [0, 1, 0]}


def ease(u):
    """Smooth start and stop (a person turning or walking does not jump to full speed)."""
    return 0.5 - 0.5 * math.cos(math.pi * u)


def turn90(first):
    eye, look = first["eye"], sub(first["target"], first["eye"])
    n = 2 * FPS
    # Linear in time (1.5 degrees every frame): the fast part is the point.
    out = [frame(eye, add(eye, rotate_y(look, math.radians(90) * i / n))) for i in range(n + 1)]
    out += [frame(eye, add(eye, rotate_y(look, math.radians(90) * (n - i) / n))) for i in range(1, n)]
    return out


def walk(first):
    eye0, target = first["eye"], first["target"]
    look = sub(target, eye0)
    n = 2 * FPS
    path = []
    for i in range(n + 1):
        u = ease(i / n)
        eye = add(eye0, scale(look, 0.4 * u))
        path.append(frame(eye, add(eye, rotate_y(look, -math.radians(30) * math.sin(math.pi * i / n)))))
    return path + path[-2:0:-1]


# Doors walked through, per scene: from, to (eye height 1.7 m). Only the pavilion has one here.
DOORS = {"pavilion": ([-4.5, 1.7, 3.0], [3.5, 1.7, 3.0])}


def door(start, end):
    ahead = sub(end, start)
    n = 3 * FPS
    path = []
    for i in range(n + 1):
        eye = add(start, scale(ahead, ease(i / n)))
        path.append(frame(eye, add(eye, ahead)))
    return path + path[-2:0:-1]


def main():
    scenes = sys.argv[1] if len(sys.argv) > 1 else os.path.join(os.path.dirname(__file__), "..", "..", "shared", "scenes")
    out = sys.argv[2] if len(sys.argv) > 2 else os.path.join(os.path.dirname(__file__), "..", "tests", "data", "camera-loops")
    os.makedirs(out, exist_ok=True)
    for sc in SCENES:
        shared = json.load(open(os.path.join(scenes, sc, "camera-loop.json")))
        first = shared["frames"][0]
        loops = [("turn90", turn90(first)), ("walk", walk(first))]
        if sc in DOORS:
            loops.append(("door", door(*DOORS[sc])))
        for name, frames in loops:
            path = os.path.join(out, f"{sc}-{name}.json")
            with open(path, "w") as f:
                json.dump({"fovY_deg": shared["fovY_deg"], "frames": frames}, f, indent=1)
                f.write("\n")
            print(f"wrote {path}: {len(frames)} frames")


if __name__ == "__main__":
    main()
