"""Reads a 3MF package or a GLB file with trimesh (an independent reader) and prints, as one
JSON object, what it found: the scene's units and world bounds, and for every placed object
its name, vertex and face counts, whether trimesh finds it watertight, its volume and its
bounds in the world (build item or node transforms applied).
Used by tests/geometry_trimesh.rs. Usage: python3 trimesh_check.py FILE"""
import json
import sys

import trimesh

scene = trimesh.load(sys.argv[1])
if not isinstance(scene, trimesh.Scene):
    scene = trimesh.Scene(scene)
objects = []
for node in scene.graph.nodes_geometry:
    transform, geometry_name = scene.graph[node]
    mesh = scene.geometry[geometry_name]
    placed = mesh.copy()
    placed.apply_transform(transform)
    objects.append(
        {
            "name": geometry_name,
            "vertices": int(len(mesh.vertices)),
            "faces": int(len(mesh.faces)),
            "watertight": bool(mesh.is_watertight),
            "winding_consistent": bool(mesh.is_winding_consistent),
            "volume": float(mesh.volume),
            "bounds": placed.bounds.tolist(),
        }
    )
print(json.dumps({"units": scene.units, "bounds": scene.bounds.tolist(), "objects": objects}))
