"""A live link between a session and two Blender objects: the base object
the artist edits (its poses go to the server, throttled) and the detailed
object that follows the session's frames. sync() does one step and never
waits for the network unless asked to; a timer calls it.

Undo: what the base sends between two of Blender's undo steps is one
gesture (one id on the Drive stream, so one entry of the session's history):
every operator that finishes and registers (those are the ones Blender
pushes undo steps for: a transform drag, a sculpt stroke) ends the gesture
its changes went into. undo() and redo() ask the session to undo this
client's latest gesture; the base object then follows the frame that
includes the result."""

from __future__ import annotations

import random
import time
from dataclasses import dataclass, field
from typing import Optional

import bpy
import numpy as np

from . import mesh_exchange, skinned_glb

JOINTS_MODEL_MATRIX = 1  # filigree.JOINTS_MODEL_MATRIX (this module loads before the package)

EDITOR, VIEWER = "EDITOR", "VIEWER"


@dataclass
class Participant:
    name: str
    pose_id: int
    vertex_count: int
    seen_version: int


@dataclass
class Person:
    """Someone in the session now (the session's presence)."""
    name: str
    editor: bool
    colour: str  # "#rrggbb", fixed for a name
    idle_seconds: float
    touching: int  # base vertices of their latest change (while under 10 s old)

    @property
    def rgb(self) -> tuple[float, float, float]:
        """The colour as Blender's colour properties take it (sRGB, 0 to 1)."""
        value = self.colour.lstrip("#")
        try:
            return tuple(int(value[i:i + 2], 16) / 255.0 for i in (0, 2, 4))
        except ValueError:
            return (0.5, 0.5, 0.5)


def operator_mark(window_manager) -> int:
    """The newest registered operator (0: none yet). Operators register when
    they finish, and those are the ones Blender pushes undo steps for."""
    operators = window_manager.operators
    return operators[-1].as_pointer() if len(operators) else 0


def set_gesture(driver, gesture_id: int) -> None:
    """The poses the driver sends from now on belong to gesture `gesture_id`
    (an older installed package has no gestures: the server then joins
    poses less than 0.5 s apart)."""
    if hasattr(type(driver), "gesture_id"):
        driver.gesture_id = gesture_id


def presence_stream(session, client_name: str):
    """The session's presence stream, on which this client is listed while
    it is open; None with a package that has none."""
    presence = getattr(session, "presence", None)
    return presence(client_name) if presence is not None else None


def poll_presence(stream) -> Optional[list]:
    """The newest presence if a new one came (never waits), as Persons."""
    snapshot = stream.poll()
    if snapshot is None:
        return None
    return [Person(p.client_name, p.role == "editor", p.colour, p.idle_seconds, len(p.touching))
            for p in snapshot.participants]


def describe(outcome, redo: bool) -> str:
    """An undo's or redo's outcome in a sentence, naming whose later work stayed."""
    what = "redo" if redo else "undo"
    if outcome.result == "nothing":
        return f"Nothing of yours to {what} in the session"
    counts: dict = {}
    for conflict in outcome.conflicts:
        counts[conflict.author] = counts.get(conflict.author, 0) + len(conflict.base_vertices)
    others = ", ".join(f"{author}'s on {n} base {'vertex' if n == 1 else 'vertices'}" for author, n in counts.items())
    if outcome.result == "conflict":
        return f"Nothing to {what}: others changed all of its vertices since ({others}); force it to overwrite them"
    done = "Redid your latest undone change" if redo else "Undid your latest change"
    return f"{done}, keeping later work ({others})" if others else done


@dataclass
class LiveLink:
    session: object  # filigree.Session
    detailed_name: str
    base_name: Optional[str]  # None for a viewer
    role: str
    client_name: str
    # Blender vertex index of each session vertex (uploaded_ids), or None when
    # the detailed object is in session order (a joined session).
    scatter: Optional[np.ndarray]
    # A skinned upload: its armature's poses go up as joints (the bones in
    # the upload's order, from the uploaded object's point of view).
    armature_name: Optional[str] = None
    source_name: Optional[str] = None
    last_joints: Optional[np.ndarray] = None
    # Frames come from a Watch stream for everyone: it sees every frame from
    # the current one on, where a Drive stream sees only those after its
    # first pose (an editor who has not edited yet must still see the others).
    watcher: object = None  # filigree.Watcher
    driver: object = None  # filigree.Driver, for an editor: poses go out through it
    positions: Optional[np.ndarray] = None  # the detailed object's coordinates, reused
    frame_buffer: Optional[np.ndarray] = None
    last_sent: Optional[np.ndarray] = None
    last_send_time: float = 0.0
    version: int = -1
    frames: int = 0
    participants: dict = field(default_factory=dict)
    base_ids: Optional[np.ndarray] = None  # base vertex j is session vertex base_ids[j]
    # Gestures: the id the base's changes go with now, whether any went with
    # it yet, and the newest registered operator seen (wm.operators).
    gesture_id: int = 0
    gesture_sent: bool = False
    operator_mark: int = 0
    # After an undo or redo (or a join): the base object follows the first
    # frame above this version; until then no pose goes out.
    resync_after: Optional[int] = None
    note: str = ""  # the latest undo's or redo's outcome, or why Ctrl+Z was Blender's; shown in the panel
    refused: str = ""  # "undo" or "redo" when the latest changed nothing for others' later work (the panel offers to force it)
    presence: object = None  # the session's presence stream (who is here), when the package has it
    people: list = field(default_factory=list)  # Person, from the newest presence

    def open(self, joined: bool = False) -> None:
        """Opens the streams: a Watch, and a Drive for an editor. A joined
        editor's base object (made at rest) follows the session's current
        pose from the first frame."""
        self.watcher = self.session.watch()
        if self.role == EDITOR:
            self.driver = self.session.drive(self.client_name)
            # Gesture ids only continue this author's latest entry; a random
            # start keeps two Blenders under one name from continuing each other's.
            self.gesture_id = random.randrange(1, 1 << 48)
            self.operator_mark = operator_mark(bpy.context.window_manager)
            self.last_sent = np.asarray(self.session.base_positions, dtype=np.float32).copy()
            if joined and not self.skinned:
                self.resync_after = -1
        detailed = bpy.data.objects[self.detailed_name]
        self.positions = mesh_exchange.vertex_positions(detailed.data).copy()
        self.frame_buffer = np.empty((self.session.vertex_count, 3), dtype=np.float32)
        self.base_ids = np.asarray(self.session.base_original_ids, dtype=np.int64)
        self.presence = presence_stream(self.session, self.client_name)

    @property
    def skinned(self) -> bool:
        """Posed through an armature: its bones are Blender's data, so Blender's undo is the one for them."""
        return self.armature_name is not None

    @property
    def alive(self) -> bool:
        return self.watcher is not None and bpy.data.objects.get(self.detailed_name) is not None

    def send_pose(self, depsgraph, min_interval: float) -> Optional[int]:
        """Sends what changed of the base object's pose since the last one
        sent (the vertices that moved, as a partial pose, so the others'
        work elsewhere stays) if `min_interval` seconds passed, in the
        current gesture; returns its pose id."""
        if self.driver is None or not self.base_name or self.resync_after is not None:
            return None
        # The throttle first: evaluating the mesh and the armature costs more than it.
        now = time.monotonic()
        if now - self.last_send_time < min_interval:
            return None
        base = bpy.data.objects.get(self.base_name)
        if base is None:
            return None
        pose = mesh_exchange.posed_positions(base, depsgraph)
        if pose.shape[0] != self.session.base_vertex_count:
            raise ValueError(f"{base.name} has {pose.shape[0]} vertices; the session's base mesh has "
                             f"{self.session.base_vertex_count} (add or remove none, and no generating modifiers)")
        joints = self._joint_pose()
        joints_changed = joints is not None and (self.last_joints is None or not np.array_equal(joints, self.last_joints))
        moved = np.flatnonzero(np.any(pose != self.last_sent, axis=1))
        if not joints_changed and moved.size == 0:
            return None
        self.last_sent, self.last_send_time = pose, now
        self._in_gesture()
        if joints_changed:
            # The armature moved: its joints (the server skins the base as
            # Blender does), not the positions they give. An edit of the base
            # in the same step goes with the next change.
            self.last_joints = joints
            return self.driver.send_joints(joints, space=JOINTS_MODEL_MATRIX)
        if moved.size == len(pose):
            return self.driver.send(pose)
        return self.driver.send_partial(moved, pose[moved])

    def _in_gesture(self) -> None:
        """The pose about to go belongs to the current gesture."""
        if not self.gesture_sent:
            set_gesture(self.driver, self.gesture_id)
            self.gesture_sent = True

    def end_gesture(self, depsgraph) -> Optional[int]:
        """Ends the current gesture: what the base shows now goes with it
        (the last step of a drag), the next change starts a new one.
        Returns the pose id of that last step, if one went."""
        sent = self.send_pose(depsgraph, 0.0)
        if self.gesture_sent:
            self.gesture_id += 1
            self.gesture_sent = False
        return sent

    def note_operators(self, window_manager, depsgraph) -> bool:
        """Ends the gesture when an operator finished since the last call
        (a new registered one: Blender pushed an undo step for it)."""
        mark = operator_mark(window_manager)
        if mark == self.operator_mark:
            return False
        self.operator_mark = mark
        self.end_gesture(depsgraph)
        return True

    def undo(self, depsgraph, redo: bool = False, force: bool = False):
        """Undoes (redoes) this client's latest gesture in the session, after
        sending what the base shows as the end of the current one. Returns
        the session's outcome; when it changed the pose, the base follows
        the frame that includes it (apply_frame)."""
        if self.driver is None or not self.base_name:
            raise ValueError("a viewer has no changes to undo")
        self.end_gesture(depsgraph)
        outcome = (self.session.redo if redo else self.session.undo)(self.client_name, force=force)
        if outcome.recorded:
            self.resync_after = outcome.accepted_at_version
        self.note = describe(outcome, redo)
        self.refused = (outcome.result == "conflict") and ("redo" if redo else "undo")
        return outcome

    def follow_base(self, frame) -> None:
        """Moves the base object's vertices the session moved (further than
        the frame's error from what the base shows) to where `frame` has
        them, and takes them as sent."""
        self.resync_after = None
        base = bpy.data.objects.get(self.base_name) if self.base_name else None
        if base is None:
            return
        target = frame.positions[self.base_ids]
        current = mesh_exchange.posed_positions(base, bpy.context.evaluated_depsgraph_get())
        tolerance = 2.0 * float(frame.max_error) + 1e-6 * float(np.abs(target).max(initial=1.0))
        moved = np.flatnonzero(np.any(np.abs(target - current) > tolerance, axis=1))
        if moved.size == 0:
            return
        mesh_exchange.offset_positions(base, moved, target[moved] - current[moved])
        # What the base shows there now is the session's: not a change to send.
        shown = mesh_exchange.posed_positions(base, bpy.context.evaluated_depsgraph_get())
        self.last_sent = self.last_sent.copy()
        self.last_sent[moved] = shown[moved]

    def _joint_pose(self) -> Optional[np.ndarray]:
        """The armature's pose as model matrices, or None without one."""
        armature = bpy.data.objects.get(self.armature_name) if self.armature_name else None
        source = bpy.data.objects.get(self.source_name) if self.source_name else None
        if armature is None or source is None:
            return None
        return skinned_glb.model_matrices(source, armature, skinned_glb.bones_in_order(armature), posed=True)

    def apply_frame(self, wait: float = 0.0):
        """Polls the newest frame (waiting up to `wait` seconds for one) and
        sets the detailed object's vertices to it; returns the frame or None."""
        if wait > 0 and not self.watcher.wait_frame(wait):
            return None
        frame = self.watcher.poll(self.frame_buffer)
        if frame is None:
            return None
        if self.scatter is None:
            self.positions[:] = frame.positions
        else:
            self.positions[self.scatter] = frame.positions
        mesh_exchange.set_positions(bpy.data.objects[self.detailed_name], self.positions)
        self.version = frame.version
        self.frames += 1
        for change in frame.changes:
            self.participants[change.client_name] = Participant(change.client_name, change.pose_id,
                                                                change.vertex_count, frame.version)
        if self.resync_after is not None and frame.version > self.resync_after:
            self.follow_base(frame)
        return frame

    def reshow(self) -> None:
        """Sets the detailed object to the newest frame applied again (after
        Blender's own undo brought back an older copy of its mesh)."""
        detailed = bpy.data.objects.get(self.detailed_name)
        if detailed is not None and self.version >= 0:
            mesh_exchange.set_positions(detailed, self.positions)

    def poll_presence(self) -> bool:
        """Takes the newest presence (who is here) if one came; True if so."""
        if self.presence is None:
            return False
        snapshot = poll_presence(self.presence)
        if snapshot is None:
            return False
        self.people = snapshot
        return True

    def sync(self, depsgraph, min_interval: float = 1.0 / 30.0, wait: float = 0.0):
        """One step: the base pose out if it changed, the newest frame in.
        (The Drive stream's own frames are decoded by its thread but not
        used; the driver's failures show in its next send.)"""
        self.send_pose(depsgraph, min_interval)
        return self.apply_frame(wait)

    def close(self) -> None:
        for stream in (self.driver, self.watcher, self.presence):
            if stream is not None:
                stream.free()
        self.driver = self.watcher = self.presence = None
        self.session.free()


# Live links by detailed object name; the timer syncs them all. A link that
# failed leaves why in ERRORS (shown in the panel) and is closed.
LINKS: dict[str, LiveLink] = {}
ERRORS: dict[str, str] = {}


def link_of(obj) -> Optional[LiveLink]:
    """The link `obj` belongs to, as its detailed or its base object."""
    if obj is None:
        return None
    for link in LINKS.values():
        if obj.name in (link.detailed_name, link.base_name):
            return link
    return None


def tick() -> Optional[float]:
    """The timer: ends the gesture of an operator that finished, syncs every
    link and takes the newest presence; a failure stops that link and shows
    in the panel."""
    if not LINKS:
        return None
    wm = bpy.context.window_manager
    rate = getattr(wm, "filigree_rate", 30.0) or 30.0
    depsgraph = bpy.context.evaluated_depsgraph_get()
    people_changed = False
    for name, link in list(LINKS.items()):
        if not link.alive:
            link.close()
            del LINKS[name]
            people_changed = True
            continue
        try:
            link.note_operators(wm, depsgraph)
            link.sync(depsgraph, 1.0 / rate)
            people_changed |= link.poll_presence()
        except Exception as e:  # noqa: BLE001  (shown in the panel, never a traceback)
            ERRORS[name] = str(e)
            print(f"Filigree: {name}: {e}")
            link.close()
            del LINKS[name]
            people_changed = True
    if people_changed:
        show_people(wm)
    for area in getattr(bpy.context.screen, "areas", []) if bpy.context.screen else []:
        if area.type == "VIEW_3D":
            area.tag_redraw()
    return 1.0 / rate


def show_people(wm) -> None:
    """Copies every link's presence into wm.filigree_people, which the panel
    draws (a colour swatch needs a property to show)."""
    people = getattr(wm, "filigree_people", None)
    if people is None:
        return
    people.clear()
    for link in LINKS.values():
        for person in link.people:
            item = people.add()
            item.name, item.session, item.colour = person.name, link.session.id, person.rgb
            item.editor, item.you, item.idle_seconds = person.editor, person.name == link.client_name, person.idle_seconds
            item.touching = person.touching


BLENDER_UNDO_NOTE = ("Blender's undo changed {base}: sent as a new change of yours, not undone in the session "
                     "(Ctrl+Z over the 3D View with {base} active undoes your gestures there)")


@bpy.app.handlers.persistent
def before_blender_undo(*_args) -> None:
    """Blender's own undo or redo is about to run (a live object was not
    active, or the Edit menu): what the base shows now ends its gesture."""
    if not LINKS:
        return
    depsgraph = bpy.context.evaluated_depsgraph_get()
    for link in LINKS.values():
        try:
            link.end_gesture(depsgraph)
        except Exception as e:  # noqa: BLE001  (the timer's next step reports a broken link)
            print(f"Filigree: {link.detailed_name}: {e}")


@bpy.app.handlers.persistent
def after_blender_undo(*_args) -> None:
    """Blender's own undo or redo ran. It may have brought back an older
    copy of the detailed mesh (shown again from the newest frame) and of
    the base: a base that changed goes to the session as a change of its
    own (Blender's undo steps are not the session's), and the panel says so."""
    if not LINKS:
        return
    depsgraph = bpy.context.evaluated_depsgraph_get()
    for link in LINKS.values():
        try:
            link.reshow()
            if link.driver is not None and link.end_gesture(depsgraph) is not None:
                link.note = BLENDER_UNDO_NOTE.format(base=link.base_name)
                print(f"Filigree: {link.note}")
        except Exception as e:  # noqa: BLE001
            print(f"Filigree: {link.detailed_name}: {e}")


_HANDLERS = ((bpy.app.handlers.undo_pre, before_blender_undo), (bpy.app.handlers.redo_pre, before_blender_undo),
             (bpy.app.handlers.undo_post, after_blender_undo), (bpy.app.handlers.redo_post, after_blender_undo))


def add_handlers() -> None:
    for handlers, function in _HANDLERS:
        if function not in handlers:
            handlers.append(function)


def remove_handlers() -> None:
    for handlers, function in _HANDLERS:
        if function in handlers:
            handlers.remove(function)


def start_timer() -> None:
    if not bpy.app.timers.is_registered(tick):
        bpy.app.timers.register(tick, first_interval=0.0, persistent=True)


def close_all() -> None:
    for link in LINKS.values():
        link.close()
    LINKS.clear()
    if bpy.app.timers.is_registered(tick):
        bpy.app.timers.unregister(tick)
