"""The per-tab Parameters folder: pick a board parameter, see its unit, bounds and value, set it.

The folder shows what the firmware's parameter table says about it (unit, bounds, default, kind, whether
it changes only in SAFE, what it does; ``host.panel.param_table``). The value goes to the board as a
``ParamSet`` (the protocol the MAVLink bridge uses) after the host checked it with the board's own rule;
the folder then shows what the board read back: confirmed, kept another value (with the board's reason),
or no answer yet.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import viser

from host.panel.board_params import BoardParams
from host.panel.param_table import PARAM_CONFIRM_S, PARAM_NAMES, ParamStatus, param_info

__all__ = ["ParamHandles", "build_param_panel", "param_text", "refresh_params"]

_ORDER_PARAMS = 60.0  # after Control (0) and View (50), before Plots (100)


@dataclass
class ParamHandles:
    """One tab's parameter editor."""

    client_id: int
    name: Any
    value: Any
    apply: Any
    read: Any
    info: Any
    shown: str = ""
    error: str = ""
    loaded: dict[str, float] = field(default_factory=dict)


def _fmt(value: float, kind: str) -> str:
    return str(int(value)) if kind in ("int", "bool") else f"{value:.6g}"


def param_text(name: str, values: dict[str, float], status: ParamStatus | None, now_s: float) -> str:
    """Markdown: the parameter's value on the board, unit, bounds, and the fate of the last set."""
    info = param_info(name)
    unit = f" {info.unit}" if info.unit else ""
    board = values.get(name)
    now = "not read yet" if board is None else f"**{_fmt(board, info.kind)}**{unit}"
    safe_only = " · **SAFE only**" if info.safety else ""
    lines = [
        f"**{name}** on the board: {now}  ",
        f"Bounds: {info.bounds} · default {_fmt(info.default, info.kind)}{unit} · {info.kind}{safe_only}",
        f"  \n{info.doc[:1].upper()}{info.doc[1:]}.",
    ]
    if status is not None:
        asked = _fmt(status.requested, info.kind)
        if status.confirmed is None:
            wait = "waiting for the board" if now_s - status.sent_s < PARAM_CONFIRM_S else "**no answer**"
            lines.append(f"  \nSet to {asked}: {wait}")
        elif status.accepted:
            lines.append(f"  \nSet to {asked}: **confirmed by the board**")
        else:
            why = f" ({status.note})" if status.note else ""
            lines.append(f"  \nSet to {asked}: **the board kept {_fmt(status.confirmed, info.kind)}**{why}")
    return "".join(lines)


def build_param_panel(client: viser.ClientHandle, model: BoardParams) -> ParamHandles:
    """Build one tab's Parameters folder (setting needs control; anyone may read)."""
    cid = client.client_id
    gui = client.gui
    first = PARAM_NAMES[0]
    with gui.add_folder("Parameters", order=_ORDER_PARAMS, expand_by_default=False):
        name = gui.add_dropdown("Parameter", PARAM_NAMES, initial_value=first)
        value = gui.add_number("Value", initial_value=param_info(first).default, step=1e-5)
        apply = gui.add_button("Set on board", color="blue", disabled=True)
        read = gui.add_button("Read all from board")
        info = gui.add_markdown("")
    h = ParamHandles(cid, name, value, apply, read, info)

    def own(event: Any) -> bool:
        return event.client_id is not None and event.client_id == cid

    @name.on_update
    def _(event: Any) -> None:
        if not own(event):
            return
        chosen = str(event.target.value)
        number: Any = value
        number.value = model.params.get(chosen, param_info(chosen).default)
        h.error = ""
        refresh_params(h, model, force=True)

    @apply.on_click
    def _(event: Any) -> None:
        if not own(event):
            return
        chosen = str(name.value)
        why = model.set_param(cid, chosen, float(value.value))
        h.error = "" if why is None else why
        if why is not None:
            client.add_notification(f"{chosen} not sent", why, color="yellow", auto_close_seconds=8.0)
        refresh_params(h, model, force=True)

    @read.on_click
    def _(event: Any) -> None:
        if own(event) and not model.request_params():
            client.add_notification(
                "Not sent", "the board link is down", color="yellow", auto_close_seconds=6
            )

    return h


def refresh_params(h: ParamHandles, model: BoardParams, force: bool = False) -> None:
    """Bring the editor in line with the board's values (sends only what changed unless forced)."""
    chosen = str(h.name.value)
    text = param_text(chosen, model.params, model.param_status.get(chosen), time.monotonic())
    if h.error:
        text += f"  \n**Not sent**: {h.error}"
    h.apply.disabled = not model.has_control(h.client_id)
    if force or text != h.shown:
        h.shown = text
        h.info.content = text
