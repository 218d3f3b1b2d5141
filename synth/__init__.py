"""Mitsuba 3 ground truth for outdoor scenes: procedural landmarks, sun/sky and HDRI
lighting, tourist-like cameras, path-traced radiance with albedo, normals, depth and
shadow buffers, written as a multi-view x multi-illumination dataset.

Import :mod:`synth.backend` (or call :func:`synth.backend.load_mitsuba`) before Mitsuba:
it selects the LLVM variant this machine supports.
"""
