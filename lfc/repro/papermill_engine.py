"""papermill's engine for this package's notebooks, ``papermill --engine lfc``:
the kernel talks over local IPC sockets, as in ``python -m lfc reproduce`` and
``sweep`` (:class:`lfc.repro.runner.IPCKernelManager`).  papermill's default
engine starts it over TCP, and the kernel then warns on stderr that its TCP
traffic is unencrypted.

Registered as the entry point ``lfc`` of the group ``papermill.engine``
(``pyproject.toml``); papermill loads it when it starts, so this module imports
only papermill's engine class.
"""

from __future__ import annotations

from papermill.engines import NBClientEngine


class IPCEngine(NBClientEngine):
    """:class:`papermill.engines.NBClientEngine` with the kernel over IPC."""

    @classmethod
    def execute_managed_notebook(cls, nb_man, kernel_name, **kwargs):
        from lfc.repro.runner import IPCKernelManager
        kwargs.setdefault("kernel_manager_class", IPCKernelManager)
        return super().execute_managed_notebook(nb_man, kernel_name, **kwargs)
