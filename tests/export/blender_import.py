# Imports PERF's mesh files into Blender (background mode) and prints what Blender made of them as
# one JSON line: `blender -b --factory-startup --python blender_import.py -- OUT_JSON MESH_DIR [RENDER_PNG]`.
# For each of mesh.obj and mesh.glb: the faces, whether a material's Base Color is an image texture
# (and which image), and the texture coordinates' range. With RENDER_PNG, also renders the textured
# OBJ with Cycles on the CPU (the picture in docs/).
import json
import sys

import bpy

args = sys.argv[sys.argv.index("--") + 1:]
out_json, mesh_dir = args[0], args[1]
render_png = args[2] if len(args) > 2 else ""

# Blender 3.4's glTF importer needs numpy (Debian: python3-numpy) and calls numpy.bool, which
# Debian 12's numpy no longer has.
try:
    import numpy
    if not hasattr(numpy, "bool"):
        numpy.bool = bool
except ImportError:
    pass  # the glTF import then fails, and the result says so


def clear():
    bpy.ops.object.select_all(action="SELECT")
    bpy.ops.object.delete()


def describe(objects):
    faces, images, uv_lo, uv_hi = 0, [], [1e9, 1e9], [-1e9, -1e9]
    for ob in objects:
        if ob.type != "MESH":
            continue
        mesh = ob.data
        faces += len(mesh.polygons)
        if mesh.uv_layers.active:
            for loop_uv in mesh.uv_layers.active.data:
                for a in range(2):
                    uv_lo[a] = min(uv_lo[a], loop_uv.uv[a])
                    uv_hi[a] = max(uv_hi[a], loop_uv.uv[a])
        for slot in ob.material_slots:
            material = slot.material
            if material is None or not material.use_nodes:
                continue
            for node in material.node_tree.nodes:
                if node.type == "BSDF_PRINCIPLED":
                    for link in node.inputs["Base Color"].links:
                        if link.from_node.type == "TEX_IMAGE" and link.from_node.image is not None:
                            image = link.from_node.image
                            images.append({"name": image.name, "size": list(image.size)})
    return {"faces": faces, "base_color_images": images, "uv_min": uv_lo, "uv_max": uv_hi}


result = {}
clear()
bpy.ops.wm.obj_import(filepath=mesh_dir + "/mesh.obj")
result["obj"] = describe(bpy.context.scene.objects)
clear()
try:
    bpy.ops.import_scene.gltf(filepath=mesh_dir + "/mesh.glb")
    result["glb"] = describe(bpy.context.scene.objects)
except Exception as e:  # reported, not hidden: the test says which importer failed
    result["glb"] = {"error": str(e)}

if render_png:
    clear()
    bpy.ops.wm.obj_import(filepath=mesh_dir + "/mesh.obj")
    meshes = [ob for ob in bpy.context.scene.objects if ob.type == "MESH"]
    points = [ob.matrix_world @ v.co for ob in meshes for v in ob.data.vertices]
    lo = [min(p[a] for p in points) for a in range(3)]
    hi = [max(p[a] for p in points) for a in range(3)]
    centre = [(lo[a] + hi[a]) / 2 for a in range(3)]
    size = max(hi[a] - lo[a] for a in range(3))
    bpy.ops.object.empty_add(location=centre)
    target = bpy.context.object
    bpy.ops.object.camera_add(location=(centre[0] + 1.3 * size, centre[1] - 1.3 * size, centre[2] + 0.8 * size))
    camera = bpy.context.object
    track = camera.constraints.new(type="TRACK_TO")
    track.target, track.track_axis, track.up_axis = target, "TRACK_NEGATIVE_Z", "UP_Y"
    bpy.context.scene.camera = camera
    world = bpy.context.scene.world or bpy.data.worlds.new("world")
    bpy.context.scene.world = world
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 1.0
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = 32
    scene.cycles.use_denoising = False  # Debian builds Cycles without OpenImageDenoise
    scene.render.resolution_x, scene.render.resolution_y = 480, 360
    scene.render.filepath = render_png
    bpy.ops.render.render(write_still=True)
    result["render"] = render_png

with open(out_json, "w") as f:
    json.dump(result, f)
