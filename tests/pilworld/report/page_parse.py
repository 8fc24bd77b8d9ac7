"""A report page parsed with the standard library: elements with their attributes and text."""

from __future__ import annotations

import base64
import binascii
from dataclasses import dataclass, field
from html.parser import HTMLParser

VOID = {"meta", "img", "br", "hr", "input", "link", "source", "col", "area", "base", "wbr", "track", "embed"}


@dataclass
class Element:
    tag: str
    attrs: dict[str, str]
    text: list[str] = field(default_factory=list)
    ids: list[str] = field(default_factory=list)  # ids of the enclosing elements, outermost first

    @property
    def classes(self) -> set[str]:
        return set(self.attrs.get("class", "").split())


class _Collector(HTMLParser):
    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.elements: list[Element] = []
        self._open: list[Element] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        el = Element(tag, {k: v or "" for k, v in attrs}, ids=[e.attrs["id"] for e in self._open if "id" in e.attrs])
        self.elements.append(el)
        if tag not in VOID:
            self._open.append(el)

    def handle_endtag(self, tag: str) -> None:
        for i in range(len(self._open) - 1, -1, -1):
            if self._open[i].tag == tag:
                del self._open[i:]
                break

    def handle_data(self, data: str) -> None:
        for el in self._open:
            el.text.append(data)


@dataclass
class Page:
    elements: list[Element]

    def find(self, tag: str, **attrs: str) -> list[Element]:
        return [e for e in self.elements if e.tag == tag and all(e.attrs.get(k) == v for k, v in attrs.items())]

    def by_id(self, ident: str) -> Element | None:
        return next((e for e in self.elements if e.attrs.get("id") == ident), None)

    def by_class(self, cls: str) -> list[Element]:
        return [e for e in self.elements if cls in e.classes]


def parse(html: str) -> Page:
    c = _Collector()
    c.feed(html)
    c.close()
    return Page(c.elements)


def text_of(el: Element) -> str:
    return " ".join(" ".join(el.text).split())


def data_payload(uri: str, mime: str) -> bytes:
    """The bytes of a ``data:<mime>;base64,…`` URI; AssertionError if it is not one."""
    prefix = f"data:{mime};base64,"
    assert uri.startswith(prefix), uri[:60]
    try:
        return base64.b64decode(uri[len(prefix) :], validate=True)
    except binascii.Error as err:  # pragma: no cover - a failing test shows it
        raise AssertionError(f"not base64: {err}") from None


def is_mp4(payload: bytes) -> bool:
    """An ISO base media file starts with a box of type ``ftyp`` (bytes 4..8)."""
    return len(payload) > 8 and payload[4:8] == b"ftyp"
