"""Executes a notebook (CI: the example must run); fails on the first cell that raises."""

import sys
import time

import nbformat
from nbclient import NotebookClient

path = sys.argv[1]
nb = nbformat.read(path, as_version=4)
t = time.perf_counter()
NotebookClient(nb, timeout=900, kernel_name="python3", resources={"metadata": {"path": "."}}).execute()
print(f"{path}: {len(nb.cells)} cells ran in {time.perf_counter() - t:.1f} s")
