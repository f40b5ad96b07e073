"""What the HTML reports share: matplotlib without a display, a figure as PNG bytes, and an
image embedded in the page with its caption."""

from __future__ import annotations

import base64
import html
import io


def pyplot():
    """matplotlib.pyplot on the Agg backend (imported on first use: it takes a second)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def png(fig, dpi: int = 110) -> bytes:
    """``fig`` as PNG bytes; the figure is closed."""
    plt = pyplot()
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=dpi)
    plt.close(fig)
    return buffer.getvalue()


def figure_html(data: bytes, caption: str, kind: str = "png") -> str:
    """An ``<figure>`` with image ``data`` (``kind``: png, jpeg) embedded and its caption."""
    return (f"<figure><img src='data:image/{kind};base64,{base64.b64encode(data).decode()}' "
            f"alt='{html.escape(caption)}'><figcaption>{html.escape(caption)}</figcaption>"
            f"</figure>")
