"""The start of a modal bake (operators.CANOPY_AO_OT_bake, frames.CANOPY_AO_OT_bake_frames):
progress bar, timer, handler and status text."""

from . import viewport


def start_modal(op, context, steps, status):
    """A modal operator's start: progress bar, timer (op._timer), handler, status text."""
    wm = context.window_manager
    wm.progress_begin(0, steps)
    op._timer = wm.event_timer_add(0.01, window=context.window)
    wm.modal_handler_add(op)
    context.workspace.status_text_set(status)
    viewport.set_status(context, "Baking: starting", 'TIME')
    return {'RUNNING_MODAL'}
