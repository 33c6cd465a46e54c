"""The paper's runtime parts (s.4): agents and their keys, the stream and unique
pools with the pose-history ring, transition slots and their queue, event delivery,
the pose texture's CPU mirror, the skinning modes, look-at turns and the read-only
frame view. Above :mod:`..meshes`.
"""
