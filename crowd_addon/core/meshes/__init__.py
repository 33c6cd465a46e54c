"""What agents are drawn with: the proxy mesh, its levels of detail (skinning-aware
decimation, far boxes, the silhouette check, switch sizes) and the bodies (variants
with props on bones). Above :mod:`..bake`.
"""
