"""Build hook: the built site stays small enough to hand around and open from disk.

The run directories under ``results/`` keep predictions, splits and logs for the commands that re-read
them; ``exclude_docs`` keeps those out of the site.  A new data file type slipping past that list would
grow the site silently, so the build fails above ``SITE_LIMIT_BYTES``, naming the heaviest folders.
"""

from __future__ import annotations

from pathlib import Path

from mkdocs.exceptions import PluginError
from mkdocs.plugins import event_priority

SITE_LIMIT_BYTES = 15_000_000


def _folder_sizes(site: Path) -> dict[str, int]:
    """Bytes under each top-level entry of the site."""
    sizes: dict[str, int] = {}
    for path in site.rglob("*"):
        if path.is_file():
            top = path.relative_to(site).parts[0]
            sizes[top] = sizes.get(top, 0) + path.stat().st_size
    return sizes


@event_priority(-100)  # after the search plugin has written its index
def on_post_build(config):
    sizes = _folder_sizes(Path(config["site_dir"]))
    total = sum(sizes.values())
    if total > SITE_LIMIT_BYTES:
        heaviest = ", ".join(
            f"{name} {size / 1e6:.1f} MB" for name, size in sorted(sizes.items(), key=lambda kv: -kv[1])[:3]
        )
        raise PluginError(
            f"the built site is {total / 1e6:.1f} MB, above {SITE_LIMIT_BYTES / 1e6:.0f} MB "
            f"(heaviest: {heaviest}); exclude data files from it in mkdocs.yml's exclude_docs"
        )
