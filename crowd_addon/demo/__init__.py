"""The stadium demo (issue 6): the show script, scene assembly, preview and export."""
