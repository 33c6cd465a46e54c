"""The crowd's GLSL sources, a resource package (read with importlib.resources).

It stays at the top of the repository, beside ``crowd_addon``, and is shipped there in
the wheel and in the Blender extension; ``crowd_addon.gpu.programs.SHADER_DIR`` finds it.
"""
