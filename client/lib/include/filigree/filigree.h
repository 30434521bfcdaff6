/*
 * filigree.h: the C API of the Filigree client, for game engines (Unity
 * P/Invoke, Unreal, Godot GDExtension) and foreign-function interfaces
 * (Python ctypes, …). Plain C99; no C++ type crosses it.
 *
 * Library: libfiligree.so (SONAME libfiligree.so.0), which exports only
 * filigree_* symbols. pkg-config: `pkg-config --cflags --libs filigree`;
 * CMake: find_package(filigree) and target_link_libraries(app filigree::c).
 *
 * Conventions
 *   - Every function returns an int status (enum filigree_status), except the
 *     few that return a string (filigree_version_string, filigree_status_name
 *     and the *_last_error functions), which never return NULL.
 *   - Handles are opaque pointers, made by one function (*out) and released
 *     by the matching *_free. A handle that is NULL, already freed, or of
 *     another kind gives FILIGREE_ERROR_INVALID_HANDLE (a freed handle is
 *     recognised unless a new handle of the same kind took its address).
 *   - Output buffers belong to the caller and come with their capacity in
 *     elements (floats, uint32s, or chars including the terminating NUL). A
 *     buffer that is too small gives FILIGREE_ERROR_BUFFER_TOO_SMALL, writes
 *     nothing to it, and stores the elements needed through `required` when
 *     that is not NULL. (NULL, 0, &required) therefore asks for the size; a
 *     NULL buffer with a nonzero capacity gives FILIGREE_ERROR_NULL_ARGUMENT.
 *   - Failures leave a message: in the handle the call was made on
 *     (filigree_client_last_error, …) and in the calling thread
 *     (filigree_last_error, also for calls that fail before a handle exists
 *     or are given a bad one). Successful calls do not clear them. A handle's
 *     message stays valid until its next failed call or its free; when
 *     several threads use one handle, prefer the thread's message.
 *   - Strings are UTF-8, NUL-terminated.
 *   - No C++ exception crosses the API: each becomes a status and a message.
 *
 * Threading
 *   - Any function may be called from any thread, and the calls on one handle
 *     are synchronised inside: e.g. the engine's game thread sends poses to a
 *     driver while its render thread polls the same driver.
 *   - Exception: *_free must be the last call on a handle, with no other
 *     thread inside a call on it. Handles may be freed in any order: a
 *     session, driver or watcher keeps the connection it came from alive.
 *   - Every driver and watcher owns one background thread that reads the
 *     stream and decodes its frames (Draco deltas → positions). A watcher's
 *     callback runs on that thread; it may call any function except
 *     filigree_watcher_close / filigree_watcher_free on its own watcher
 *     (FILIGREE_ERROR_WRONG_THREAD). While the callback runs, that watcher
 *     receives nothing: copy and return (the server skips frames for a slow
 *     watcher and never waits for it).
 *   - What blocks: filigree_create_session, filigree_join and
 *     filigree_close_session (network round trips; an upload lasts as long as
 *     the server preprocesses), the history calls (filigree_undo, _redo, the
 *     checkpoints', filigree_history_read, filigree_set_presence,
 *     filigree_history_export_next), *_close (until the stream has ended),
 *     filigree_watcher_wait and filigree_presence_wait. Sends block only
 *     while the transport is flow-controlled. Polls never wait for the
 *     network. A presence handle owns a background thread as a watcher does.
 *
 * Usage (errors unchecked for brevity):
 *
 *   filigree_client* client;
 *   filigree_session* session;
 *   filigree_driver* driver;
 *   filigree_connect("127.0.0.1:50051", NULL, &client);
 *   filigree_create_session(client, bytes, size, "obj", NULL, "my-engine", &session);
 *   size_t n, m;
 *   filigree_session_vertex_count(session, &n);       // detailed mesh: what you render
 *   filigree_session_base_vertex_count(session, &m);  // base mesh: what you pose
 *   filigree_driver_open(session, NULL, "my-engine", &driver);
 *   for (uint64_t tick = 1; running; ++tick) {
 *     filigree_driver_send_positions(driver, tick, pose, 3 * m);
 *     uint64_t version, pose_id;
 *     int updated;
 *     if (filigree_driver_poll(driver, vertex_buffer, 3 * n, &version, &pose_id, &updated) != FILIGREE_OK)
 *       fprintf(stderr, "%s\n", filigree_driver_last_error(driver));
 *     else if (updated) upload_to_gpu(vertex_buffer);
 *   }
 *   filigree_driver_close(driver);
 *   filigree_driver_free(driver);
 *   filigree_session_free(session);
 *   filigree_client_free(client);
 *
 * C# (Unity) P/Invoke: handles are IntPtr, size_t is UIntPtr (or nuint),
 * uint64_t is ulong, strings are UTF-8:
 *
 *   [DllImport("filigree")] static extern int filigree_connect(
 *       [MarshalAs(UnmanagedType.LPUTF8Str)] string target, IntPtr options, out IntPtr client);
 *   [DllImport("filigree")] static extern int filigree_driver_send_positions(
 *       IntPtr driver, ulong poseId, float[] positions, UIntPtr floatCount);
 *   [DllImport("filigree")] static extern int filigree_driver_poll(
 *       IntPtr driver, float[] positions, UIntPtr capacity, out ulong version, out ulong poseId, out int updated);
 *   [DllImport("filigree")] static extern IntPtr filigree_driver_last_error(IntPtr driver);
 *       // Marshal.PtrToStringUTF8(...)
 *   delegate void FrameCallback(IntPtr positions, UIntPtr floatCount, ulong version, IntPtr user);
 *       // [UnmanagedFunctionPointer(CallingConvention.Cdecl)]; keep the delegate alive while the watcher lives
 */
#ifndef FILIGREE_FILIGREE_H
#define FILIGREE_FILIGREE_H

#include <stddef.h>
#include <stdint.h>

#if defined(_WIN32)
/* Untested: the library is only built for Linux here. */
#if defined(FILIGREE_C_BUILD)
#define FILIGREE_API __declspec(dllexport)
#else
#define FILIGREE_API __declspec(dllimport)
#endif
#else
#define FILIGREE_API
#endif

#ifdef __cplusplus
extern "C" {
#endif

/* ------------------------------------------------------------ status codes */

/* 1…16 are the gRPC status codes with the same numbers (what the server
 * answered, or the client library's equivalent); 100 and up are this API's. */
typedef enum filigree_status {
  FILIGREE_OK = 0,
  FILIGREE_CANCELLED = 1,
  FILIGREE_UNKNOWN = 2,
  FILIGREE_INVALID_ARGUMENT = 3, /* malformed mesh or pose, wrong sizes, bad index */
  FILIGREE_DEADLINE_EXCEEDED = 4, /* also: filigree_watcher_wait timed out */
  FILIGREE_NOT_FOUND = 5,         /* unknown or closed session, unknown clip */
  FILIGREE_ALREADY_EXISTS = 6,
  FILIGREE_PERMISSION_DENIED = 7, /* wrong token, or a viewer token where an editor's is needed */
  FILIGREE_RESOURCE_EXHAUSTED = 8,
  FILIGREE_FAILED_PRECONDITION = 9, /* e.g. joints for a session without a skeleton */
  FILIGREE_ABORTED = 10,
  FILIGREE_OUT_OF_RANGE = 11, /* also: a joint or clip index ≥ its count */
  FILIGREE_UNIMPLEMENTED = 12,
  FILIGREE_INTERNAL = 13,
  FILIGREE_UNAVAILABLE = 14, /* server down or restarting, session moving between replicas: retry */
  FILIGREE_DATA_LOSS = 15,   /* a frame that does not decode, inconsistent session data */
  FILIGREE_UNAUTHENTICATED = 16,

  FILIGREE_ERROR_INVALID_HANDLE = 100,   /* NULL, freed, or another kind of handle */
  FILIGREE_ERROR_BUFFER_TOO_SMALL = 101, /* `required` says how many elements */
  FILIGREE_ERROR_NULL_ARGUMENT = 102,    /* a pointer that must not be NULL was */
  FILIGREE_ERROR_OUT_OF_MEMORY = 103,
  FILIGREE_ERROR_STREAM_ENDED = 104, /* the stream ended normally (closed): nothing more to send or poll */
  FILIGREE_ERROR_WRONG_THREAD = 105  /* a watcher closed or freed from its own callback */
} filigree_status;

/* "OK", "NOT_FOUND", "ERROR_BUFFER_TOO_SMALL", …; "UNKNOWN_STATUS" for other values. */
FILIGREE_API const char* filigree_status_name(int status);

/* The library's version, "MAJOR.MINOR.PATCH". */
FILIGREE_API const char* filigree_version_string(void);

/* The message of the calling thread's latest failed call ("" if none). Valid
 * until that thread's next failed call. */
FILIGREE_API const char* filigree_last_error(void);

/* ------------------------------------------------------------ connection */

typedef struct filigree_client filigree_client;
typedef struct filigree_session filigree_session;
typedef struct filigree_driver filigree_driver;
typedef struct filigree_watcher filigree_watcher;

/* TLS settings. Passing options at all means TLS; each field may be NULL:
 * no pem_root_certs means the system's roots; pem_cert_chain and
 * pem_private_key (both or neither) authenticate the client. */
typedef struct filigree_connect_options {
  const char* pem_root_certs;
  const char* pem_cert_chain;
  const char* pem_private_key;
} filigree_connect_options;

/* A channel to `target` ("127.0.0.1:50051", "dns:///host:port"), insecure
 * when `options` is NULL. Connects lazily: a server that is down makes the
 * first call that needs it fail with FILIGREE_UNAVAILABLE. */
FILIGREE_API int filigree_connect(const char* target, const filigree_connect_options* options, filigree_client** out);

/* Threads each driver or watcher opened afterwards (from this client's
 * sessions) uses to decode one frame; 0 (the default) means the hardware's.
 * Engines that keep their cores busy may want 1 or 2. */
FILIGREE_API int filigree_client_set_decode_threads(filigree_client* client, uint32_t threads);

/* The API key filigree_create_session presents to a server started with
 * --api-keys (NULL or "": none). Set it before creating sessions from this
 * client; the key is kept in memory only. */
FILIGREE_API int filigree_client_set_api_key(filigree_client* client, const char* api_key);

FILIGREE_API const char* filigree_client_last_error(const filigree_client* client);

/* Releases the handle; the connection closes once no session, driver or
 * watcher made from it is left. NULL is accepted and ignored (FILIGREE_OK). */
FILIGREE_API int filigree_client_free(filigree_client* client);

/* ------------------------------------------------------------ sessions */

/* How the server preprocesses an upload (SessionOptions in the contract).
 * Zero fields mean the server's defaults, so {0} is a valid value. */
typedef struct filigree_session_options {
  uint32_t base_vertices;     /* target base size in vertices, or 0 */
  double base_ratio;          /* target base size as a fraction of the vertices, or 0 */
  double threshold;           /* performance threshold T of the cut; 0: direct recovery only */
  int32_t whole_mesh;         /* nonzero: whole-mesh optimisation (T = infinity) */
  uint32_t quantization_bits; /* frame deltas, 8…24 bits; 0: chosen per frame */
  int32_t skinning;           /* skinned glTF uploads: 0 linear blend, 1 dual quaternion */
} filigree_session_options;

/* Uploads a mesh file's bytes (`format`: "obj", "ply", "off", "gltf", "glb")
 * and waits while the server preprocesses it. `options` may be NULL (the
 * server's defaults); `client_name` may be NULL. The new session carries the
 * editor and viewer tokens. */
FILIGREE_API int filigree_create_session(filigree_client* client, const void* mesh_bytes, size_t size,
                                         const char* format, const filigree_session_options* options,
                                         const char* client_name, filigree_session** out);

/* Joins an existing session with either of its tokens. */
FILIGREE_API int filigree_join(filigree_client* client, const char* session_id, const char* token,
                               filigree_session** out);

/* Strings, copied with their NUL (`capacity` and `required` count it). The
 * tokens are empty for a joined session. */
FILIGREE_API int filigree_session_id(const filigree_session* session, char* buffer, size_t capacity, size_t* required);
FILIGREE_API int filigree_session_editor_token(const filigree_session* session, char* buffer, size_t capacity,
                                               size_t* required);
FILIGREE_API int filigree_session_viewer_token(const filigree_session* session, char* buffer, size_t capacity,
                                               size_t* required);

/* n: vertices of the detailed (rest) mesh, what frames carry and you render. */
FILIGREE_API int filigree_session_vertex_count(const filigree_session* session, size_t* count);
/* m: vertices of the base mesh, what poses move. */
FILIGREE_API int filigree_session_base_vertex_count(const filigree_session* session, size_t* count);

/* The meshes, as they were when the session was made or joined. Positions
 * are x y z interleaved (3·n or 3·m floats), faces 3 indices each. Rest
 * arrays are in the session's vertex order (frames use it); uploaded_ids[i]
 * is the vertex of the uploaded file that session vertex i is. Base arrays
 * are in base order (poses use it); base_original_ids[j] is the session
 * vertex that base vertex j is. */
FILIGREE_API int filigree_session_rest_positions(const filigree_session* session, float* buffer, size_t capacity,
                                                 size_t* required);
FILIGREE_API int filigree_session_rest_faces(const filigree_session* session, uint32_t* buffer, size_t capacity,
                                             size_t* required);
FILIGREE_API int filigree_session_uploaded_ids(const filigree_session* session, uint32_t* buffer, size_t capacity,
                                               size_t* required);
FILIGREE_API int filigree_session_base_positions(const filigree_session* session, float* buffer, size_t capacity,
                                                 size_t* required);
FILIGREE_API int filigree_session_base_faces(const filigree_session* session, uint32_t* buffer, size_t capacity,
                                             size_t* required);
FILIGREE_API int filigree_session_base_original_ids(const filigree_session* session, uint32_t* buffer,
                                                    size_t capacity, size_t* required);

/* The skeleton of a skinned glTF/GLB upload (0 joints and clips otherwise).
 * Joints are in skeleton order, parents before children; parent -1 is a
 * root. joint_rest gives the rest local transform, 10 floats (translation
 * xyz, rotation quaternion xyzw, scale xyz). An index ≥ the count gives
 * FILIGREE_OUT_OF_RANGE. */
FILIGREE_API int filigree_session_joint_count(const filigree_session* session, size_t* count);
FILIGREE_API int filigree_session_joint_name(const filigree_session* session, size_t joint, char* buffer,
                                             size_t capacity, size_t* required);
FILIGREE_API int filigree_session_joint_parent(const filigree_session* session, size_t joint, int32_t* parent);
FILIGREE_API int filigree_session_joint_rest(const filigree_session* session, size_t joint, float* buffer,
                                             size_t capacity, size_t* required);
FILIGREE_API int filigree_session_clip_count(const filigree_session* session, size_t* count);
FILIGREE_API int filigree_session_clip_name(const filigree_session* session, size_t clip, char* buffer,
                                            size_t capacity, size_t* required);
FILIGREE_API int filigree_session_clip_duration(const filigree_session* session, size_t clip, double* seconds);

/* Replaces the handles of `client_name` (NULL: "filigree-c") with these
 * (editor token; NULL: the session's): detailed-mesh vertex vertices[k]
 * (session order, < n) should go to targets 3k…3k+2. The server moves the
 * base as rigidly as it can to meet every participant's handles, on top of
 * the poses. vertex_count 0 removes this client's handles.
 * *handles_in_session (may be NULL) gets every participant's handle count. */
FILIGREE_API int filigree_set_handles(filigree_session* session, const char* token, const char* client_name,
                                      const uint32_t* vertices, size_t vertex_count, const float* targets,
                                      size_t float_count, uint32_t* handles_in_session);

/* As filigree_set_handles, as part of a gesture (a drag): calls with the
 * same nonzero `gesture_id` are one history entry, undone as one; 0: calls
 * less than 0.5 s apart are one entry. */
FILIGREE_API int filigree_set_handles_in_gesture(filigree_session* session, const char* token,
                                                 const char* client_name, uint64_t gesture_id,
                                                 const uint32_t* vertices, size_t vertex_count, const float* targets,
                                                 size_t float_count, uint32_t* handles_in_session);

/* Sets the performance threshold T of the cut (editor token; NULL: the
 * session's); whole_mesh nonzero means T = infinity. Thresholds must be
 * finite and >= 0. Every participant's frames follow from the next one. */
FILIGREE_API int filigree_set_threshold(filigree_session* session, const char* token, double threshold,
                                        int whole_mesh);

/* Ends the session on the server for everyone (editor token; NULL: the one
 * the session was made or joined with). The handle stays to be freed. */
FILIGREE_API int filigree_close_session(filigree_session* session, const char* token);

FILIGREE_API const char* filigree_session_last_error(const filigree_session* session);
/* Releases the handle (the session goes on on the server). NULL: FILIGREE_OK. */
FILIGREE_API int filigree_session_free(filigree_session* session);

/* ------------------------------------------------------------ frames */

/* What one decoded frame was, besides its positions. */
typedef struct filigree_frame_info {
  uint64_t version;         /* the session's frame number */
  uint64_t pose_id;         /* for a driver: its newest pose the frame includes (0: none) */
  uint64_t encoded_bytes;   /* compressed size on the wire */
  uint64_t frames_received; /* frames decoded by this stream so far, polled or not */
  float max_error;          /* largest |decoded − exact| coordinate error of the frame */
  int32_t keyframe;         /* 1: a keyframe, 0: a sparse frame */
} filigree_frame_info;

/* With a callback, a watcher hands each decoded frame to it on its
 * background thread: 3·n floats, valid only during the call. */
typedef void (*filigree_frame_callback)(const float* positions, size_t float_count, uint64_t version, void* user);

/* ------------------------------------------------------------ driving */

typedef enum filigree_joint_space {
  FILIGREE_JOINTS_LOCAL_TRS = 0,   /* 10 floats per joint: translation xyz, quaternion xyzw, scale xyz */
  FILIGREE_JOINTS_MODEL_MATRIX = 1 /* 16 floats per joint: 4×4 model matrix, column-major */
} filigree_joint_space;

/* Opens a Drive stream (editor token; NULL: the one the session was made or
 * joined with). Its background thread starts decoding the frames that come
 * back. A refused token or a closed session shows in a later send or poll. */
FILIGREE_API int filigree_driver_open(filigree_session* session, const char* token, const char* client_name,
                                      filigree_driver** out);

/* Sends a full pose: 3·m floats, base order. `pose_id` must increase from
 * one pose to the next; frames echo it. Sizes are checked here, so a
 * malformed pose gives FILIGREE_INVALID_ARGUMENT and the stream goes on.
 * Once the stream has ended, returns why (FILIGREE_ERROR_STREAM_ENDED
 * after filigree_driver_close or a normal end). */
FILIGREE_API int filigree_driver_send_positions(filigree_driver* driver, uint64_t pose_id, const float* positions,
                                                size_t float_count);

/* Sends a partial pose: base vertices indices[k] (< m) move to positions
 * 3k…3k+2; float_count must be 3·index_count. The others keep their place. */
FILIGREE_API int filigree_driver_send_partial(filigree_driver* driver, uint64_t pose_id, const uint32_t* indices,
                                              size_t index_count, const float* positions, size_t float_count);

/* Sends a skeletal pose (sessions with a skeleton): `values` holds 10 or 16
 * floats per joint as `space` says (filigree_joint_space), for the joints
 * `joints` (joint_count indices), or for all joints in order when `joints`
 * is NULL (joint_count is then ignored). Joints not named keep their
 * previous transform. The server skins the base mesh. */
FILIGREE_API int filigree_driver_send_joints(filigree_driver* driver, uint64_t pose_id, int space,
                                             const uint32_t* joints, size_t joint_count, const float* values,
                                             size_t value_count);

/* The gesture the poses sent from now on belong to (a drag, a slider's
 * travel): poses of one nonzero id are one history entry, undone as one
 * (filigree_undo). Use a new id for each gesture (a counter will do); 0
 * (the default) ends it: the server then joins poses less than 0.5 s apart. */
FILIGREE_API int filigree_driver_set_gesture(filigree_driver* driver, uint64_t gesture_id);

/* Copies the newest decoded frame into `positions` (3·n floats, session
 * order) if it is newer than the last one polled, and sets *updated to 1;
 * otherwise leaves `positions` alone and sets *updated to 0. Frames in
 * between are skipped. `version`, `pose_id` and `updated` may be NULL; they
 * describe the latest frame polled. capacity < 3·n gives
 * FILIGREE_ERROR_BUFFER_TOO_SMALL whether or not a frame is waiting. Once
 * the stream has ended and its last frame was polled, returns why it ended
 * (FILIGREE_ERROR_STREAM_ENDED for a normal end). Never waits for the
 * network. */
FILIGREE_API int filigree_driver_poll(filigree_driver* driver, float* positions, size_t capacity, uint64_t* version,
                                      uint64_t* pose_id, int* updated);

/* The latest polled frame (frames_received counts every decoded one). */
FILIGREE_API int filigree_driver_frame_info(const filigree_driver* driver, filigree_frame_info* info);

/* Waits up to timeout_ms (negative: without limit; 0: just checks) for a
 * frame newer than the last one polled: FILIGREE_OK when poll will return
 * one, FILIGREE_DEADLINE_EXCEEDED when none came in time, and once the
 * stream has ended without one, why it ended (as poll). */
FILIGREE_API int filigree_driver_wait_frame(filigree_driver* driver, int64_t timeout_ms);

/* Waits up to timeout_ms (negative: without limit; 0: just checks) for a
 * frame that includes this driver's pose `pose_id` (or a later pose of it):
 * FILIGREE_OK when filigree_driver_poll will return it, or returned it
 * already; FILIGREE_DEADLINE_EXCEEDED when none came in time; once the
 * stream has ended without one, why it ended (as poll). Newer frames that
 * do not include it yet are left for poll. The usual loop of an engine that
 * must see its pose before it goes on:
 *   filigree_driver_send_positions(driver, id, pose, 3 * m);
 *   if (filigree_driver_wait_for_pose(driver, id, 1000) == FILIGREE_OK)
 *     filigree_driver_poll(driver, vertices, 3 * n, NULL, NULL, NULL); */
FILIGREE_API int filigree_driver_wait_for_pose(filigree_driver* driver, uint64_t pose_id, int64_t timeout_ms);

/* Who changed the session in the frames up to the latest one polled (since
 * the poll before it): one line per participant, by name,
 * "client_name<TAB>newest pose_id<TAB>base vertices moved<LF>" (tabs and line
 * breaks in names become spaces; the vertex counts of several frames add
 * up). "" when nobody did. A string, as filigree_session_id. */
FILIGREE_API int filigree_driver_changes(const filigree_driver* driver, char* buffer, size_t capacity,
                                         size_t* required);

/* How many times the stream has begun to reconnect: a driver whose server
 * went away (a restart, a failover) reopens its stream by itself, re-sending
 * the poses no frame acknowledged, for up to 60 s; then it ends with why.
 * Sends meanwhile are accepted and wait for the new stream. A count that
 * grew since the last tick tells an engine its link is recovering. */
FILIGREE_API int filigree_driver_reconnects(const filigree_driver* driver, uint64_t* count);

/* Ends the stream: tells the server no more poses come, waits for the
 * server to end the stream and the background thread to stop, and returns
 * the stream's status (FILIGREE_OK for a normal end; else why it failed).
 * The newest frame can still be polled. Idempotent. */
FILIGREE_API int filigree_driver_close(filigree_driver* driver);

FILIGREE_API const char* filigree_driver_last_error(const filigree_driver* driver);
/* Cancels the stream if it was not closed, then releases the handle. NULL: FILIGREE_OK. */
FILIGREE_API int filigree_driver_free(filigree_driver* driver);

/* ------------------------------------------------------------ watching */

/* Opens a Watch stream (either token; NULL: the session's): the session's
 * frames newer than `after_version`, as they are computed. The stream
 * reconnects by itself when the server goes away (a restart, a failover),
 * from the last frame it decoded, for up to 60 s; then it ends with why. With a callback,
 * frames go to it (on the background thread) and cannot be polled; without,
 * filigree_watcher_poll gets them. `callback` and `user` may be NULL. */
FILIGREE_API int filigree_watcher_open(filigree_session* session, const char* token, uint64_t after_version,
                                       filigree_frame_callback callback, void* user, filigree_watcher** out);

/* How filigree_watcher_open_with watches (WatchRequest in the contract).
 * Zero fields mean the defaults, so {0} is a valid value. */
typedef struct filigree_watch_options {
  uint64_t after_version; /* as filigree_watcher_open's */
  /* A level of detail: frames of a coarser mesh of at most this many
   * vertices (0: full detail). Budgets round down to a power of two; below
   * the base's vertex count m they get the base, at or above n the full
   * mesh. Frames then carry k ≤ n vertices, those of the level
   * (filigree_watcher_level_*), and filigree_watcher_set_detail changes it. */
  uint32_t max_vertices;
} filigree_watch_options;

/* As filigree_watcher_open, with every option of the contract; `options`
 * may be NULL (the defaults: from the current frame, at full detail). */
FILIGREE_API int filigree_watcher_open_with(filigree_session* session, const char* token,
                                            const filigree_watch_options* options, filigree_frame_callback callback,
                                            void* user, filigree_watcher** out);

/* Plays the session's clip `clip` (its name, see filigree_session_clip_name)
 * on the server (editor token; NULL: the session's) at `speed` (0 means 1),
 * looping while `loop` is nonzero: a watcher over the frames of the clip,
 * which ends normally after the clip's last sample unless looping. The same
 * as filigree_play_clip_with with start_seconds and max_rate 0. */
FILIGREE_API int filigree_play_clip(filigree_session* session, const char* token, const char* clip, double speed,
                                    int loop, filigree_frame_callback callback, void* user, filigree_watcher** out);

/* How filigree_play_clip_with plays a clip (PlayClipRequest in the
 * contract). Zero fields mean the defaults, so {0} is a valid value. */
typedef struct filigree_clip_playback {
  double speed;         /* playback rate, finite and >= 0; 0 means 1 */
  int32_t loop;         /* nonzero: play until the watcher is closed */
  double start_seconds; /* clip time of the first sample, finite */
  double max_rate;      /* samples per second at most, finite and >= 0; 0: as fast as frames compute, up to 60 */
} filigree_clip_playback;

/* As filigree_play_clip, with every option of the contract; `options` may be
 * NULL (the defaults: from the start, at speed 1, once). A speed or max_rate
 * that is negative or not finite, or a start_seconds that is not finite,
 * gives FILIGREE_INVALID_ARGUMENT and no watcher. Each frame's pose_id
 * numbers the newest sample it includes, and filigree_watcher_clip_seconds
 * gives that sample's clip time. */
FILIGREE_API int filigree_play_clip_with(filigree_session* session, const char* token, const char* clip,
                                         const filigree_clip_playback* options, filigree_frame_callback callback,
                                         void* user, filigree_watcher** out);

/* As filigree_driver_poll (pose_id is 0 for a Watch stream; for a clip,
 * the server's number of the sample). A watcher with a callback gives
 * FILIGREE_FAILED_PRECONDITION. */
FILIGREE_API int filigree_watcher_poll(filigree_watcher* watcher, float* positions, size_t capacity,
                                       uint64_t* version, uint64_t* pose_id, int* updated);

/* The latest frame polled, or handed to the callback. */
FILIGREE_API int filigree_watcher_frame_info(const filigree_watcher* watcher, filigree_frame_info* info);

/* For a clip's watcher: the clip time, in seconds, of the newest sample the
 * latest frame polled (or handed to the callback) includes. A clip that
 * does not loop goes from the playback's start_seconds up to its duration,
 * which its last frame shows; a looping one wraps around to 0. 0 when that
 * frame includes no sample, before the first frame, and for Watch streams. */
FILIGREE_API int filigree_watcher_clip_seconds(const filigree_watcher* watcher, double* seconds);

/* Levels of detail (filigree_watch_options.max_vertices). Each frame is at
 * a level: a mesh of k vertices of the detailed mesh, in ascending session
 * order, and faces between them. A polled frame holds 3·k floats, x y z of
 * the level's vertices in order (capacity 3·n always fits; at a level poll
 * needs 3·k for the level of the frame waiting), and these functions
 * describe the level of the latest frame polled (or handed to the
 * callback), so that the positions and the level go together:
 *   - level_vertex_count: k (n at full detail; 0 before the first frame);
 *   - level_original_ids: k session vertex ids, level vertex i is session
 *     vertex ids[i] (its rest position is that vertex's);
 *   - level_faces: 3 indices into the level's vertices per triangle.
 * At full detail (k = n) the level is the rest mesh itself and both arrays
 * are empty: use the session's rest faces (filigree_session_rest_faces). A
 * level's vertex count identifies it: when k changes from one poll to the
 * next, read the ids and faces again. Arrays as filigree_session_rest_faces. */
FILIGREE_API int filigree_watcher_level_vertex_count(const filigree_watcher* watcher, size_t* count);
FILIGREE_API int filigree_watcher_level_original_ids(const filigree_watcher* watcher, uint32_t* buffer,
                                                     size_t capacity, size_t* required);
FILIGREE_API int filigree_watcher_level_faces(const filigree_watcher* watcher, uint32_t* buffer, size_t capacity,
                                              size_t* required);

/* Moves a watcher opened with a vertex budget to the level of `max_vertices`
 * (>= 1; rounded as filigree_watch_options.max_vertices): the stream then
 * sends that level and its frames. *vertex_count (may be NULL) gets the
 * level's k; frames of it follow the ones in flight, so poll until
 * level_vertex_count says k. Waits for the stream's first message if it has
 * not come yet, then one round trip. FILIGREE_FAILED_PRECONDITION for a
 * watcher opened at full detail or a clip's, and while it reconnects (try
 * again); FILIGREE_NOT_FOUND once its stream has ended on the server. */
FILIGREE_API int filigree_watcher_set_detail(filigree_watcher* watcher, uint32_t max_vertices, uint32_t* vertex_count);

/* How many times the stream has begun to reconnect (as filigree_driver_reconnects). */
FILIGREE_API int filigree_watcher_reconnects(const filigree_watcher* watcher, uint64_t* count);

/* As filigree_driver_wait_frame and filigree_driver_changes (with a
 * callback, the changes are the handed frame's, and wait_frame gives
 * FILIGREE_FAILED_PRECONDITION). */
FILIGREE_API int filigree_watcher_wait_frame(filigree_watcher* watcher, int64_t timeout_ms);
FILIGREE_API int filigree_watcher_changes(const filigree_watcher* watcher, char* buffer, size_t capacity,
                                          size_t* required);

/* Waits up to timeout_ms (negative: without limit; 0: just checks) for the
 * stream to end, e.g. a clip to finish playing: returns the stream's status
 * (FILIGREE_OK for a normal end), or FILIGREE_DEADLINE_EXCEEDED if it is
 * still going. */
FILIGREE_API int filigree_watcher_wait(filigree_watcher* watcher, int64_t timeout_ms);

/* Stops watching now (cancels the stream), waits for the background thread
 * and returns FILIGREE_OK, or why the stream had failed before. Idempotent.
 * Not from the watcher's own callback. */
FILIGREE_API int filigree_watcher_close(filigree_watcher* watcher);

FILIGREE_API const char* filigree_watcher_last_error(const filigree_watcher* watcher);
/* Closes the watcher if needed and releases the handle. NULL: FILIGREE_OK.
 * Not from the watcher's own callback. */
FILIGREE_API int filigree_watcher_free(filigree_watcher* watcher);

/* ------------------------------------------------------------ working together */

/* Every accepted change is a history entry of its author: the client_name
 * of the poses (filigree_driver_open), handles or threshold. Poses of one
 * gesture (filigree_driver_set_gesture) are one entry, undone as one. An
 * author's undo never undoes another's change, and keeps the vertices others
 * changed since (the conflicts) unless forced. */

/* What an undo, a redo or a checkpoint's restore did. */
typedef enum filigree_edit_result {
  FILIGREE_EDIT_DONE = 0,     /* every vertex restored */
  FILIGREE_EDIT_PARTIAL = 1,  /* restored but the conflicts' vertices, which keep the others' work */
  FILIGREE_EDIT_CONFLICT = 2, /* every vertex conflicts: nothing changed */
  FILIGREE_EDIT_NOTHING = 3   /* nothing to undo or redo */
} filigree_edit_result;

typedef struct filigree_edit_outcome {
  int32_t result;                 /* filigree_edit_result */
  uint32_t conflict_count;        /* later changes of other authors that kept their vertices */
  uint64_t entry;                 /* the change undone or redone (a restore: the new entry) */
  uint64_t recorded;              /* the history entry this made; 0 if nothing changed */
  uint64_t accepted_at_version;   /* every frame with a larger version includes the result */
  uint64_t conflict_vertex_count; /* base vertices they kept, over all conflicts */
} filigree_edit_outcome;

/* Undoes `client_name`'s (NULL: "filigree-c") latest change not undone
 * (editor token; NULL: the session's), on the base vertices nobody else changed since; with `force`
 * nonzero, those too (the others' change is overwritten there). `outcome`
 * may be NULL. The outcome's message and conflicts:
 * filigree_session_edit_message and filigree_session_edit_conflicts. */
FILIGREE_API int filigree_undo(filigree_session* session, const char* token, const char* client_name, int force,
                               filigree_edit_outcome* outcome);
/* Redoes `client_name`'s latest undone change (since its last new one); as filigree_undo. */
FILIGREE_API int filigree_redo(filigree_session* session, const char* token, const char* client_name, int force,
                               filigree_edit_outcome* outcome);

/* The latest undo, redo or restore made through this handle: what it did,
 * in a sentence; and its conflicts, one line each,
 * "author<TAB>entry<TAB>base vertices separated by spaces<LF>" (tabs and
 * line breaks in names become spaces), "" when none. Strings, as
 * filigree_session_id; "" before the first. */
FILIGREE_API int filigree_session_edit_message(const filigree_session* session, char* buffer, size_t capacity,
                                               size_t* required);
FILIGREE_API int filigree_session_edit_conflicts(const filigree_session* session, char* buffer, size_t capacity,
                                                 size_t* required);

typedef struct filigree_checkpoint {
  uint64_t id;
  double time;          /* when it was made, Unix seconds */
  uint64_t version;     /* the session's version then */
  uint64_t after_entry; /* the newest history entry it includes (0: none) */
} filigree_checkpoint;

/* Names the current pose and threshold (editor token; NULL: the
 * session's): `name` 1 to 200 bytes, `client_name` its author (NULL:
 * "filigree-c"). `checkpoint` (may be NULL) gets it. */
FILIGREE_API int filigree_create_checkpoint(filigree_session* session, const char* token, const char* name,
                                            const char* client_name, filigree_checkpoint* checkpoint);
/* Goes back to checkpoint `id` (editor token): itself a history entry of
 * `client_name`, so filigree_undo takes it back. FILIGREE_NOT_FOUND: no
 * such checkpoint. `outcome` may be NULL. */
FILIGREE_API int filigree_restore_checkpoint(filigree_session* session, const char* token, uint64_t id,
                                             const char* client_name, filigree_edit_outcome* outcome);

typedef struct filigree_checkpoint_diff {
  uint64_t checkpoint;
  uint64_t version;      /* the current pose's */
  uint64_t vertex_count; /* base vertices that differ */
  double max_distance;   /* in the mesh's units */
  double rms_distance;   /* over every base vertex */
  int32_t threshold_differs;
} filigree_checkpoint_diff;

/* The current base pose against checkpoint `id` (either token). `diff`
 * must not be NULL. The base vertices that differ go to `vertices`
 * (vertex_count of them) by the buffer rules, except that a NULL `vertices`
 * with capacity 0 asks for `diff` alone (FILIGREE_OK). */
FILIGREE_API int filigree_diff_checkpoint(filigree_session* session, const char* token, uint64_t id,
                                          filigree_checkpoint_diff* diff, uint32_t* vertices, size_t capacity,
                                          size_t* required);

/* The history as read at one moment: a handle (immutable, so any thread
 * may read it) with the entries, oldest first, and the checkpoints. */
typedef struct filigree_history filigree_history;

typedef enum filigree_history_kind {
  FILIGREE_HISTORY_POSE = 0,      /* poses, partial poses or joints: base vertices moved */
  FILIGREE_HISTORY_HANDLES = 1,   /* the author's handles (and the pose solved from them) */
  FILIGREE_HISTORY_THRESHOLD = 2, /* the threshold */
  FILIGREE_HISTORY_RESTORE = 3,   /* a checkpoint restored (target: its id) */
  FILIGREE_HISTORY_UNDO = 4,      /* the author undid entry `target` */
  FILIGREE_HISTORY_REDO = 5       /* the author redid entry `target` */
} filigree_history_kind;

typedef struct filigree_history_info {
  uint64_t entry_count;
  uint64_t checkpoint_count;
  uint64_t first_seq; /* entries below it were dropped to keep the history in its bounds */
  uint64_t bytes;     /* what the history holds on the server */
} filigree_history_info;

typedef struct filigree_history_entry {
  uint64_t seq;          /* increasing within the session */
  int32_t kind;          /* filigree_history_kind */
  int32_t undone;        /* 1: undone and not redone since */
  double start_time;     /* Unix seconds */
  double end_time;       /* its last change */
  uint64_t target;       /* RESTORE: the checkpoint; UNDO, REDO: the entry */
  uint64_t gesture_id;
  uint64_t version;      /* the session's version at its last change */
  uint64_t vertex_count; /* base vertices it changed (filigree_history_entry_vertices) */
} filigree_history_entry;

/* Reads the history (either token; NULL: the session's); `newest` > 0:
 * only the newest that many entries. */
FILIGREE_API int filigree_history_read(filigree_session* session, const char* token, uint32_t newest,
                                       filigree_history** out);
FILIGREE_API int filigree_history_info_get(const filigree_history* history, filigree_history_info* info);
/* Entry `index` (0: the oldest read); an index >= entry_count gives FILIGREE_OUT_OF_RANGE. */
FILIGREE_API int filigree_history_entry_get(const filigree_history* history, size_t index,
                                            filigree_history_entry* entry);
FILIGREE_API int filigree_history_entry_author(const filigree_history* history, size_t index, char* buffer,
                                               size_t capacity, size_t* required);
/* The base vertices entry `index` changed (base order). */
FILIGREE_API int filigree_history_entry_vertices(const filigree_history* history, size_t index, uint32_t* buffer,
                                                 size_t capacity, size_t* required);
/* Checkpoint `index` (0 … checkpoint_count - 1), its name and author. */
FILIGREE_API int filigree_history_checkpoint_get(const filigree_history* history, size_t index,
                                                 filigree_checkpoint* checkpoint);
FILIGREE_API int filigree_history_checkpoint_name(const filigree_history* history, size_t index, char* buffer,
                                                  size_t capacity, size_t* required);
FILIGREE_API int filigree_history_checkpoint_author(const filigree_history* history, size_t index, char* buffer,
                                                    size_t capacity, size_t* required);
FILIGREE_API const char* filigree_history_last_error(const filigree_history* history);
/* NULL: FILIGREE_OK. */
FILIGREE_API int filigree_history_free(filigree_history* history);

/* ---- presence: who is here and what they touch */

typedef struct filigree_presence filigree_presence;

typedef struct filigree_participant {
  int32_t role;           /* 0: viewer, 1: editor */
  uint32_t colour;        /* 0xRRGGBB, fixed for a name */
  int32_t has_pointer;    /* 1: pointer and pointer_vertex are set */
  float pointer[3];       /* where it points on the mesh */
  uint32_t pointer_vertex; /* the detailed-mesh vertex nearest the pointer */
  double idle_seconds;    /* since its last change, pointer move or join */
  uint64_t touching_count; /* base vertices of its latest change, while under 10 s old */
  uint64_t handle_count;   /* detailed-mesh vertices of its handles */
} filigree_participant;

/* Opens a presence stream (either token; NULL: the session's), on which
 * `client_name` (NULL: "filigree-c") is listed as present while it is open.
 * Its background thread keeps the newest presence for filigree_presence_poll;
 * it reconnects by itself as a watcher does. */
FILIGREE_API int filigree_presence_open(filigree_session* session, const char* token, const char* client_name,
                                        filigree_presence** out);
/* Takes the newest presence if it is newer than the last one polled
 * (*updated 1; else 0 and nothing changes); the participant functions below
 * describe the presence polled. `version` (may be NULL) gets the session's
 * version it was made at. Once the stream has ended and its last presence
 * was polled, returns why (FILIGREE_ERROR_STREAM_ENDED for a normal end).
 * Never waits. */
FILIGREE_API int filigree_presence_poll(filigree_presence* presence, uint64_t* version, int* updated);
/* Waits up to timeout_ms (negative: without limit; 0: just checks) for a
 * presence newer than the last one polled: FILIGREE_OK, FILIGREE_DEADLINE_EXCEEDED,
 * or why the stream ended. */
FILIGREE_API int filigree_presence_wait(filigree_presence* presence, int64_t timeout_ms);
/* Participants of the polled presence, by name (0 before the first poll). */
FILIGREE_API int filigree_presence_participant_count(const filigree_presence* presence, size_t* count);
FILIGREE_API int filigree_presence_participant_get(const filigree_presence* presence, size_t index,
                                                   filigree_participant* participant);
FILIGREE_API int filigree_presence_participant_name(const filigree_presence* presence, size_t index, char* buffer,
                                                    size_t capacity, size_t* required);
FILIGREE_API int filigree_presence_participant_touching(const filigree_presence* presence, size_t index,
                                                        uint32_t* buffer, size_t capacity, size_t* required);
FILIGREE_API int filigree_presence_participant_handles(const filigree_presence* presence, size_t index,
                                                       uint32_t* buffer, size_t capacity, size_t* required);
/* Stops the stream, waits for the background thread and returns FILIGREE_OK
 * or why the stream had failed before. Idempotent. */
FILIGREE_API int filigree_presence_close(filigree_presence* presence);
FILIGREE_API const char* filigree_presence_last_error(const filigree_presence* presence);
/* Closes if needed and releases the handle. NULL: FILIGREE_OK. */
FILIGREE_API int filigree_presence_free(filigree_presence* presence);

/* Sets `client_name`'s pointer (either token; NULL: the session's):
 * `pointer` x y z on the mesh and the nearest detailed-mesh vertex; a NULL
 * `pointer` clears it. */
FILIGREE_API int filigree_set_presence(filigree_session* session, const char* token, const char* client_name,
                                       const float* pointer, uint32_t pointer_vertex);

/* ---- export: the state after each history entry */

typedef struct filigree_history_export filigree_history_export;

typedef struct filigree_history_state {
  uint64_t entry;   /* the state after this history entry */
  uint64_t version; /* the session's version at that entry's last change */
  double time;      /* that change's time, Unix seconds */
  float max_error;  /* largest |decoded − exact| coordinate error of its positions */
} filigree_history_state;

/* Exports the states after the history entries from `from_entry` to
 * `to_entry` (0: the oldest kept, the newest), oldest first (either token;
 * NULL: the session's), each deformed at full detail (T = 0) as the
 * session's frames are. At most 2000 entries at a time. */
FILIGREE_API int filigree_export_history(filigree_session* session, const char* token, uint64_t from_entry,
                                         uint64_t to_entry, filigree_history_export** out);
/* Blocks for the next state: its positions (3·n floats, session order: the
 * detailed mesh) into `positions` by the buffer rules (checked before
 * anything is read), and `state` (may be NULL). FILIGREE_ERROR_STREAM_ENDED
 * once every state was read; else why the stream failed
 * (FILIGREE_INVALID_ARGUMENT: a range the server refused). */
FILIGREE_API int filigree_history_export_next(filigree_history_export* history_export, float* positions,
                                              size_t capacity, size_t* required, filigree_history_state* state);
/* The latest state read: its author (a string, as filigree_session_id) and
 * its base pose (3·m floats, base order: what replaying it would submit). */
FILIGREE_API int filigree_history_export_author(const filigree_history_export* history_export, char* buffer,
                                                size_t capacity, size_t* required);
FILIGREE_API int filigree_history_export_base_pose(const filigree_history_export* history_export, float* buffer,
                                                   size_t capacity, size_t* required);
/* Ends the stream (cancels what is left) and returns FILIGREE_OK, or why it
 * had failed. Idempotent; from any thread, also to wake a blocked next. */
FILIGREE_API int filigree_history_export_close(filigree_history_export* history_export);
FILIGREE_API const char* filigree_history_export_last_error(const filigree_history_export* history_export);
/* Closes if needed and releases the handle. NULL: FILIGREE_OK. */
FILIGREE_API int filigree_history_export_free(filigree_history_export* history_export);

#ifdef __cplusplus
}
#endif

#endif /* FILIGREE_FILIGREE_H */
