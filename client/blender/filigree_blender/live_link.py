"""A live link between a session and two Blender objects: the base object
the artist edits (its poses go to the server, throttled) and the detailed
object that follows the session's frames. sync() does one step and never
waits for the network unless asked to; a timer calls it."""

from __future__ import annotations

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

    def open(self) -> None:
        """Opens the streams: a Watch, and a Drive for an editor."""
        self.watcher = self.session.watch()
        if self.role == EDITOR:
            self.driver = self.session.drive(self.client_name)
        detailed = bpy.data.objects[self.detailed_name]
        self.positions = mesh_exchange.vertex_positions(detailed.data).copy()
        self.frame_buffer = np.empty((self.session.vertex_count, 3), dtype=np.float32)

    @property
    def alive(self) -> bool:
        return self.watcher is not None and bpy.data.objects.get(self.detailed_name) is not None

    def send_pose(self, depsgraph, min_interval: float) -> Optional[int]:
        """Sends the base object's pose if it changed since the last one sent
        and `min_interval` seconds passed; returns its pose id."""
        if self.driver is None or not self.base_name:
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
        if not joints_changed and self.last_sent is not None and np.array_equal(pose, self.last_sent):
            return None
        self.last_sent, self.last_send_time = pose, now
        if joints_changed:
            # The armature moved: its joints (the server skins the base as
            # Blender does), not the positions they give. An edit of the base
            # in the same step goes with the next change.
            self.last_joints = joints
            return self.driver.send_joints(joints, space=JOINTS_MODEL_MATRIX)
        return self.driver.send(pose)

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
        return frame

    def sync(self, depsgraph, min_interval: float = 1.0 / 30.0, wait: float = 0.0):
        """One step: the base pose out if it changed, the newest frame in.
        (The Drive stream's own frames are decoded by its thread but not
        used; the driver's failures show in its next send.)"""
        self.send_pose(depsgraph, min_interval)
        return self.apply_frame(wait)

    def close(self) -> None:
        for stream in (self.driver, self.watcher):
            if stream is not None:
                stream.free()
        self.driver = self.watcher = None
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
    """The timer: syncs every link; a failure stops that link and shows in the panel."""
    if not LINKS:
        return None
    rate = getattr(bpy.context.window_manager, "filigree_rate", 30.0) or 30.0
    depsgraph = bpy.context.evaluated_depsgraph_get()
    for name, link in list(LINKS.items()):
        if not link.alive:
            link.close()
            del LINKS[name]
            continue
        try:
            link.sync(depsgraph, 1.0 / rate)
        except Exception as e:  # noqa: BLE001  (shown in the panel, never a traceback)
            ERRORS[name] = str(e)
            print(f"Filigree: {name}: {e}")
            link.close()
            del LINKS[name]
    for area in getattr(bpy.context.screen, "areas", []) if bpy.context.screen else []:
        if area.type == "VIEW_3D":
            area.tag_redraw()
    return 1.0 / rate


def start_timer() -> None:
    if not bpy.app.timers.is_registered(tick):
        bpy.app.timers.register(tick, first_interval=0.0, persistent=True)


def close_all() -> None:
    for link in LINKS.values():
        link.close()
    LINKS.clear()
    if bpy.app.timers.is_registered(tick):
        bpy.app.timers.unregister(tick)
