"""What the forkserver of the mesh reader processes (`bridge.robots.mesh_readers`) imports
once, before it forks them: trimesh, without the optional packages a daemon leaves out
(`bridge.robots.mesh_extras`). Each reader then starts with it imported, in milliseconds."""

from bridge.robots.mesh_extras import leave_out_mesh_extras

leave_out_mesh_extras()

import bridge.robots.meshes  # noqa: E402,F401  - imported for the readers forked after it
