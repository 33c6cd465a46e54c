"""Chunked exports, one process or a Dask cluster (``crowd export --workers N``).

A shot's export split in chunks runs in three steps, each its own function so a
render-farm queue can run them as plain command lines too (docs/snapshots.md):

1. :func:`.chunks.write_shot_snapshots` (``crowd snapshot``): one cheap pass of the
   simulation writes the snapshot before each chunk;
2. :func:`.chunks.export_chunk` (``crowd export --frames A-B --snapshots DIR``), once
   per chunk, anywhere: the crowd built as a single export builds it, started from the
   chunk's snapshot;
3. :func:`crowd_addon.usd.stitch.stitch` (``crowd stitch``): the chunks joined into one
   stage.

:func:`.cluster.farm_export` (``crowd export --workers N``) runs the three as tasks of a
Dask cluster: a ``LocalCluster`` of ``workers`` processes by default, or an existing
scheduler. :func:`.cluster.farm_export_shots` (``crowd farm SHOTS_JSON``,
:func:`.shot_list.load_shot_list`) runs many shots' tasks on one cluster at once. Each
snapshot pass and chunk is a task retried once (:mod:`.tasks`), the chunks wait for
their shot's snapshots and the stitch for its chunks;
progress from every worker shows as one ``chunks done/total`` count; a chunk that fails
twice is reported by name with its error, and then nothing is stitched, so a stage
already at the output is left as it was: the chunks exported again write new layer
versions and keep the ones that stage reads (usd/references.py). The report says
whether it is so: it compares the files the stage read before the run with what is
there after it. Every attempt is logged in
``<stem>.chunks/attempts.log`` (time, chunk, worker, outcome; a failure with its
traceback). A cluster that does not start (workers killed as they start: "Nanny failed
to start") or fails while the shots run is a CrowdError naming it, its traceback in
every shot's attempts log; Dask's own log lines go there too, never to the terminal.
Dask is the optional ``farm`` extra (``pip install .[farm]``); it is imported only
in :mod:`.cluster`, only when a cluster is used.

Modules: :mod:`.chunks` (a shot's source, its chunks and the steps one process runs),
:mod:`.tasks` (the workers' tasks and the attempts log they write), :mod:`.cluster`
(the Dask cluster: tasks submitted, results collected, a failed run's stage checked)
and :mod:`.shot_list` (``crowd farm``'s shot list file).
"""
