"""Format the result report: Markdown tables and cells, paths, and the HTML page.

The HTML rendering is self-contained: PNGs and MP4 videos are embedded as data URIs.
"""

from __future__ import annotations

import base64
import html
import os
import re
from pathlib import Path
from typing import Any

IMAGE_RE = re.compile(r'!\[([^\]]*)\]\(([^)\s]+)\)')
VIDEO_LINK_RE = re.compile(r'<a href="([^"]+\.mp4)">(.*?)</a>')
VIDEO_EMBED_LIMIT = 8 * 2**20  # bytes; a larger video is referenced next to the report instead
PLAY = '▶'  # starts the text of a video's link in Result.md


def display_path(path: Path, fallback: str | None = None) -> str:
    """Show a path as the report does.

    As given when relative, else relative to the working directory when inside it, else
    ``fallback`` (no machine-specific paths when avoidable).
    """
    path = Path(path)
    if not path.is_absolute():
        return path.as_posix()
    relative = os.path.relpath(path, Path.cwd())
    return relative if not relative.startswith('..') else (fallback or path.as_posix())


def cell(value: Any) -> str:
    """Format a table cell: one line, pipes escaped."""
    text = '–' if value is None else str(value)
    return ' '.join(text.split()).replace('|', '\\|')


def table(header: list[str] | tuple[str, ...], rows: list[list[Any]]) -> list[str]:
    """Format a Markdown table (followed by a blank line)."""
    lines = ['| ' + ' | '.join(header) + ' |', '|' + '---|' * len(header)]
    return lines + ['| ' + ' | '.join(cell(v) for v in row) + ' |' for row in rows] + ['']


def pct(value: Any, digits: int = 0) -> str:
    """Format a fraction as a percentage ('–' for None)."""
    return '–' if value is None else f'{100 * float(value):.{digits}f}%'


def num(value: Any, digits: int = 2) -> str:
    """Format a number with fixed decimals ('–' for None)."""
    return '–' if value is None else f'{float(value):.{digits}f}'


def duration(seconds: Any) -> str:
    """Format seconds as hours/minutes with the total seconds in brackets."""
    if seconds is None:
        return '–'
    minutes, secs = divmod(int(round(float(seconds))), 60)
    hours, minutes = divmod(minutes, 60)
    text = f'{hours} h {minutes:02d} min' if hours else f'{minutes} min {secs:02d} s'
    return f'{text} ({float(seconds):,.0f} s)'


def missing(what: str, command: str) -> list[str]:
    """Say that an input is missing and which command produces it."""
    return [f'> **Missing:** {what}. Produce it with `{command}`.', '']


def details(summary: str, body: list[str]) -> list[str]:
    """Wrap Markdown in a collapsed block (a blank line after the summary)."""
    return [f'<details><summary>{summary}</summary>', '', *body, '</details>', '']


def image(path: str, caption: str) -> list[str]:
    """Show an image with its caption below."""
    return [f'![{caption}]({path})', '', f'*{caption}*', '']


def video_link(path: str, caption: str) -> list[str]:
    """Link a video (Markdown has no player); ``to_html`` turns the link into one."""
    return [f'[{PLAY} {caption}]({path})', '']


HTML_PAGE = """<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>Result: {title}</title><style>
body {{font-family: sans-serif; max-width: 1150px; margin: 2em auto; padding: 0 1em;
      line-height: 1.45; color: #222}}
table {{border-collapse: collapse; margin: 0.6em 0; font-size: 0.92em}}
th, td {{border: 1px solid #bbb; padding: 3px 8px; vertical-align: top}}
th {{background: #eee}} img, video {{max-width: 100%}} summary {{cursor: pointer}}
pre {{background: #f4f4f4; padding: 0.6em; overflow-x: auto}} code {{background: #f4f4f4}}
blockquote {{border-left: 4px solid #d33; margin: 0.6em 0; padding: 0.1em 0.8em}}
</style></head><body>
{body}
</body></html>
"""


def video_player(match: re.Match[str], folder: Path) -> str:
    """Replace a rendered link to an MP4 beside the report by a ``<video>`` element.

    The file is embedded as a data URI up to ``VIDEO_EMBED_LIMIT`` (the page stays
    self-contained), else referenced relative to the page.
    """
    target, caption = html.unescape(match.group(1)), match.group(2).removeprefix(PLAY + ' ')
    path = folder / target
    if not path.is_file():
        return match.group(0)
    if path.stat().st_size <= VIDEO_EMBED_LIMIT:
        data = base64.b64encode(path.read_bytes()).decode()
        source, label = f'data:video/mp4;base64,{data}', f'<em>{caption}</em>'
    else:
        source = html.escape(target)
        label = f'<a href="{source}">{caption}</a>'
    return f'<video controls preload="metadata" src="{source}"></video><br>{label}'


def to_html(text: str, folder: Path, title: str) -> str:
    """Render the report as a stand-alone HTML page.

    PNGs and MP4 videos are embedded as base64 data URIs (a video over ``VIDEO_EMBED_LIMIT``
    is referenced relative to the page).
    """
    try:
        import markdown  # Python-Markdown, installed with tensorboard
        text = re.sub(r'<details>', '<details markdown="1">', text)  # render what is inside
        body = markdown.markdown(text, extensions=['tables', 'fenced_code', 'md_in_html'])
    except ImportError:  # readable fallback: the Markdown source with the images inlined
        body = '<pre>' + IMAGE_RE.sub(lambda m: f'</pre><img alt="{m.group(1)}" '
                                      f'src="{m.group(2)}"><pre>', html.escape(text)) + '</pre>'

    def embed(match: re.Match[str]) -> str:
        path = folder / html.unescape(match.group(1))
        if path.suffix.lower() != '.png' or not path.is_file():
            return match.group(0)
        return f'src="data:image/png;base64,{base64.b64encode(path.read_bytes()).decode()}"'
    body = re.sub(r'src="([^"]+)"', embed, body)
    body = VIDEO_LINK_RE.sub(lambda m: video_player(m, folder), body)
    return HTML_PAGE.format(title=html.escape(title), body=body)
