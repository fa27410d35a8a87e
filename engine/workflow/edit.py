"""The saved edit of a session: read (including what older versions wrote) and written."""

from __future__ import annotations

from engine.checks import check_kappa
from engine.errors import InputError, SessionError
from engine.session import Session
from engine.session.edit import Edit, EditAcquisition, EditTarget, mask_name
from engine.workflow.decomposition import decomposition_key

__all__ = ["edit_from_plan", "interrupted_edit", "save_edit", "saved_edit"]


def saved_edit(session: Session) -> Edit | None:
    """The session's saved edit, reading what older versions wrote; None if it has none.

    ``state["edit"]`` (this schema), else the app's ``state["edits"]`` (version 1), else the
    command line's old ``state["edit"] = {"kappa": ...}`` completed from the plan, else — for
    a session whose capture finished — the plan's targets with their fixed κ (the last one 1).

    Raises
    ------
    SessionError
        The stored edit does not fit the schema (the message names the field).
    """
    state = session.state
    try:
        edit = state.get("edit")
        if isinstance(edit, dict) and "version" in edit:
            return Edit.from_json(edit, "state.edit")
        if isinstance(state.get("edits"), dict):
            return Edit.from_json(state["edits"], "state.edits")
    except InputError as exc:
        raise SessionError(f"session {session.path}: {exc}") from None
    plan = state.get("plan")
    if plan is None or state.get("status") != "captured":
        return None
    if isinstance(edit, dict):  # the command line's old edit: recolored plainly, as it was then
        return edit_from_plan(session, edit["kappa"], noise_aware=False)
    return edit_from_plan(session)


def edit_from_plan(session: Session, kappa=(1.0, 1.0, 1.0), *, denoise: int = 0, noise_aware: bool = True) -> Edit:
    """The edit of a captured plan: its targets with their fixed κ, the last one with ``kappa``.

    ``noise_aware`` (default True, as for every new acquisition) chooses the noise-aware recolor.

    Raises
    ------
    SessionError
        The session has no plan.
    """
    plan = session.state.get("plan")
    if plan is None:
        raise SessionError(f"session {session.path} has no acquisition: run `albedit capture` first")
    targets = _plan_targets(session, plan, kappa)
    cascade = tuple(plan["targets"])
    return Edit(targets=targets, current=cascade[-1],
                acquisition=EditAcquisition(cascade, tuple(t.kappa for t in targets), decomposition_key(session),
                                            int(denoise), bool(noise_aware)))


def interrupted_edit(session: Session) -> Edit | None:
    """The edit of an acquisition that did not finish and was never saved: its plan's targets (κ as
    planned, the last one's 1) and nothing acquired, so the same plan can be resumed.

    None when the session holds a saved edit, no plan, or a finished one (:func:`saved_edit` reads those).
    """
    state = session.state
    plan = state.get("plan")
    if plan is None or state.get("status") == "captured" or saved_edit(session) is not None:
        return None
    targets = _plan_targets(session, plan, (1.0, 1.0, 1.0))
    return Edit(targets=targets, current=targets[-1].name)


def _plan_targets(session: Session, plan: dict, kappa) -> tuple[EditTarget, ...]:
    """The plan's targets in cascade order, with their fixed κ and the last one's ``kappa``."""
    masks = set(session.masks)
    kappas = [tuple(k) for k in plan["fixed_kappa"]] + [tuple(float(v) for v in check_kappa(kappa, 3))]
    targets = []
    for name, digest, kap in zip(plan["targets"], plan["masks"], kappas, strict=True):
        stored = mask_name(name, digest)
        targets.append(EditTarget(name, stored if stored in masks or name not in masks else name, kap))
    return tuple(targets)


def save_edit(session: Session, edit: Edit) -> None:
    """Write ``edit`` into the session's state (replacing any edit an older version wrote)."""
    session.update(edit=edit.to_json(), edits=None)
