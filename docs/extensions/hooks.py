"""MkDocs hooks of the site."""

from __future__ import annotations

import os
from typing import Any

from mkdocs.plugins import event_priority

#: pages whose address is not their file's: the notebook tutorial would share
#: ``tutorial/`` with the Markdown tutorial of the same stem
ADDRESSES = {"tutorial.ipynb": "notebook/"}


@event_priority(-100)  # after the notebook plugin has made its pages
def on_files(files: Any, config: Any) -> Any:
    for file in files:
        address = ADDRESSES.get(file.src_uri)
        if address is not None:
            file.dest_path = f"{address}index.html"
            file.abs_dest_path = os.path.normpath(os.path.join(config["site_dir"],
                                                               file.dest_path))
            file.url = address
    return files
