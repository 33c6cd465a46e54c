"""The sample stadium builder and its modules, a resource package (read with
importlib.resources: ``crowd_addon.demo.run`` runs ``build_stadium.py`` from it).

``build_stadium.py`` is a script (it imports its sibling modules by putting this
folder on ``sys.path``); nothing imports this package for its code.
"""
