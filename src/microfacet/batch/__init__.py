"""Batches: one per-file task (``bake``, ``glints``, ``fit``) over a folder, in this
process, on local worker processes or on a Dask distributed cluster.

```python
rows = mf.batch.run("bake", "maps/", "pyramids/", recursive=True, scale=2.0)          # local cores
rows = mf.batch.run("glints", "maps/", "ms/", scheduler="tcp://10.0.0.1:8786")       # a Dask cluster
```

See :func:`microfacet.batch.runner.run` for the guarantees (atomic outputs, resumable,
failures reported per file, summary.csv/summary.md).
"""
from ..io.names import input_name
from .runner import execute, format_summary_csv, format_summary_markdown, run
from .tasks import TASKS, Task, bake_file, fit_file, get_task, glints_file

__all__ = ["run", "execute", "Task", "TASKS", "get_task", "bake_file", "glints_file", "fit_file",
           "input_name", "format_summary_csv", "format_summary_markdown"]
