/*
 * engine_loop_c: engine_loop.cpp's game loop through the C API (filigree.h),
 * in C99: what a Unity, Unreal or Godot binding does.
 *
 *   engine_loop_c [--server HOST:PORT] --mesh FILE [--frames N] [--rate HZ]
 *   FILIGREE_TOKEN=EDITOR_TOKEN engine_loop_c [--server HOST:PORT] --session ID [--frames N] [--rate HZ]
 *
 * It uploads a mesh (or joins a session), then for N ticks at HZ sends a
 * procedural bend of the base mesh and polls the newest decoded frame into
 * the vertex buffer a renderer would draw, all from this one thread (the
 * library decodes on its own). At the end it prints the frames received and
 * their mean compressed size, and closes what it opened.
 *
 * Build against the installed package (CMake: filigree::c), or directly:
 *   cc -std=c99 engine_loop_c.c -o engine_loop_c $(pkg-config --cflags --libs filigree) -lm
 */
#define _POSIX_C_SOURCE 200809L /* nanosleep */

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include <filigree/filigree.h>

static const char* const kUsage =
    "usage: engine_loop_c [--server HOST:PORT] (--mesh FILE | --session ID, with $FILIGREE_TOKEN the editor token)\n"
    "                     [--frames N] [--rate HZ]\n";

struct args {
  const char* server;
  const char* mesh;
  const char* session;
  const char* token;
  long frames;
  double rate;
};

/* 0 on success; prints why not. */
static int parse_args(int argc, char** argv, struct args* a) {
  int i;
  a->server = "127.0.0.1:50051";
  a->mesh = a->session = a->token = NULL;
  a->frames = 120;
  a->rate = 60.0;
  for (i = 1; i < argc; ++i) {
    const char* flag = argv[i];
    const char* value;
    if (strcmp(flag, "-h") == 0 || strcmp(flag, "--help") == 0) {
      fputs(kUsage, stdout);
      exit(0);
    }
    if (i + 1 >= argc) {
      fprintf(stderr, "engine_loop_c: missing value after %s\n%s", flag, kUsage);
      return 1;
    }
    value = argv[++i];
    if (strcmp(flag, "--server") == 0) a->server = value;
    else if (strcmp(flag, "--mesh") == 0) a->mesh = value;
    else if (strcmp(flag, "--session") == 0) a->session = value;
    else if (strcmp(flag, "--frames") == 0) a->frames = strtol(value, NULL, 10);
    else if (strcmp(flag, "--rate") == 0) a->rate = strtod(value, NULL);
    else {
      fprintf(stderr, "engine_loop_c: unknown option %s\n%s", flag, kUsage);
      return 1;
    }
  }
  a->token = getenv("FILIGREE_TOKEN"); /* never an argument: command lines are visible to every user */
  if ((a->mesh == NULL) == (a->session == NULL) || (a->session != NULL && a->token == NULL)) {
    fprintf(stderr, "engine_loop_c: give --mesh FILE, or --session ID with FILIGREE_TOKEN set\n%s", kUsage);
    return 1;
  }
  if (a->frames <= 0 || !(a->rate > 0.0)) {
    fprintf(stderr, "engine_loop_c: --frames and --rate must be positive\n");
    return 1;
  }
  return 0;
}

/* The whole file in a malloc'd buffer (NULL if it cannot be read). */
static char* read_file(const char* path, size_t* size) {
  FILE* f = fopen(path, "rb");
  char* bytes = NULL;
  long length;
  if (!f) return NULL;
  if (fseek(f, 0, SEEK_END) == 0 && (length = ftell(f)) >= 0 && fseek(f, 0, SEEK_SET) == 0) {
    bytes = malloc(length > 0 ? (size_t)length : 1);
    if (bytes && fread(bytes, 1, (size_t)length, f) != (size_t)length) {
      free(bytes);
      bytes = NULL;
    }
    *size = (size_t)length;
  }
  fclose(f);
  return bytes;
}

/* The engine's animation, a stand-in for a skeleton: the half of the base
 * mesh beyond the middle of its longest axis a rotates in the plane of a and
 * the next axis b, by up to ±40° at its tip, swinging at 0.5 Hz. */
static void bend(const float* rest, size_t m, double t, float* out) {
  const double kPi = 3.14159265358979323846;
  float lo[3] = {1e30f, 1e30f, 1e30f}, hi[3] = {-1e30f, -1e30f, -1e30f};
  double mid, half, center_b, max_angle;
  size_t i, v;
  int a = 0, b, c;
  for (i = 0; i < 3 * m; ++i) {
    if (rest[i] < lo[i % 3]) lo[i % 3] = rest[i];
    if (rest[i] > hi[i % 3]) hi[i % 3] = rest[i];
  }
  for (c = 1; c < 3; ++c)
    if (hi[c] - lo[c] > hi[a] - lo[a]) a = c;
  b = (a + 1) % 3;
  mid = 0.5 * (lo[a] + hi[a]);
  half = 0.5 * (hi[a] - lo[a]);
  if (half < 1e-12) half = 1e-12;
  center_b = 0.5 * (lo[b] + hi[b]);
  max_angle = 40.0 * kPi / 180.0 * sin(2.0 * kPi * 0.5 * t);
  memcpy(out, rest, 3 * m * sizeof(float));
  for (v = 0; v < m; ++v) {
    const double u = rest[3 * v + a] - mid, db = rest[3 * v + b] - center_b;
    double angle;
    if (u <= 0.0) continue;
    angle = max_angle * (u / half);
    out[3 * v + a] = (float)(mid + u * cos(angle) - db * sin(angle));
    out[3 * v + b] = (float)(center_b + u * sin(angle) + db * cos(angle));
  }
}

static void sleep_seconds(double seconds) {
  struct timespec ts;
  ts.tv_sec = (time_t)seconds;
  ts.tv_nsec = (long)((seconds - (double)ts.tv_sec) * 1e9);
  nanosleep(&ts, NULL);
}

/* Prints a failed call and its message; returns 1 for main. */
static int report(const char* what, int status, const char* message) {
  fprintf(stderr, "engine_loop_c: %s: %s (%s)\n", what, filigree_status_name(status), message);
  return 1;
}

int main(int argc, char** argv) {
  struct args args;
  filigree_client* client = NULL;
  filigree_session* session = NULL;
  filigree_driver* driver = NULL;
  float *base = NULL, *pose = NULL, *vertices = NULL;
  size_t n = 0, m = 0;
  long tick;
  uint64_t last_pose = 0, newest = 0, frames = 0, bytes = 0;
  int rc, status = 1;

  if (parse_args(argc, argv, &args) != 0) return 2;
  printf("libfiligree %s\n", filigree_version_string());

  /* 1. A connection and a session: upload the mesh, or join one. */
  if ((rc = filigree_connect(args.server, NULL, &client)) != FILIGREE_OK)
    return report("connect", rc, filigree_last_error());
  if (args.mesh) {
    size_t size = 0;
    char* mesh = read_file(args.mesh, &size);
    const char* dot = strrchr(args.mesh, '.');
    char id[64];
    if (!mesh) {
      fprintf(stderr, "engine_loop_c: cannot read %s\n", args.mesh);
      goto done;
    }
    rc = filigree_create_session(client, mesh, size, dot ? dot + 1 : "obj", NULL, "engine_loop_c", &session);
    free(mesh);
    if (rc != FILIGREE_OK) {
      report("create session", rc, filigree_client_last_error(client));
      goto done;
    }
    if (filigree_session_id(session, id, sizeof id, NULL) == FILIGREE_OK) printf("session %s\n", id);
  } else if ((rc = filigree_join(client, args.session, args.token, &session)) != FILIGREE_OK) {
    report("join", rc, filigree_client_last_error(client));
    goto done;
  }

  /* 2. The sizes and the base mesh to pose; the vertex buffer frames land in
   *    (an engine would poll straight into its mapped or staging buffer). */
  filigree_session_vertex_count(session, &n);
  filigree_session_base_vertex_count(session, &m);
  printf("%lu vertices, %lu base vertices\n", (unsigned long)n, (unsigned long)m);
  base = malloc(3 * m * sizeof(float));
  pose = malloc(3 * m * sizeof(float));
  vertices = malloc(3 * n * sizeof(float));
  if (!base || !pose || !vertices) {
    fprintf(stderr, "engine_loop_c: out of memory\n");
    goto done;
  }
  if ((rc = filigree_session_base_positions(session, base, 3 * m, NULL)) != FILIGREE_OK) {
    report("base positions", rc, filigree_session_last_error(session));
    goto done;
  }

  /* 3. The game loop: a pose out, the newest frame in, every tick. */
  if ((rc = filigree_driver_open(session, NULL, "engine_loop_c", &driver)) != FILIGREE_OK) {
    report("drive", rc, filigree_session_last_error(session));
    goto done;
  }
  for (tick = 1; tick <= args.frames + (long)(2.0 * args.rate); ++tick) {
    uint64_t version = 0, pose_id = 0;
    int updated = 0;
    if (tick <= args.frames) {
      bend(base, m, (double)tick / args.rate, pose);
      if ((rc = filigree_driver_send_positions(driver, (uint64_t)tick, pose, 3 * m)) != FILIGREE_OK) {
        report("send", rc, filigree_driver_last_error(driver));
        goto done;
      }
      last_pose = (uint64_t)tick;
    } else if (newest >= last_pose) {
      break; /* the last pose came back: no need for the grace ticks */
    }
    if ((rc = filigree_driver_poll(driver, vertices, 3 * n, &version, &pose_id, &updated)) != FILIGREE_OK) {
      report("poll", rc, filigree_driver_last_error(driver));
      goto done;
    }
    if (updated) {
      filigree_frame_info info = {0};
      filigree_driver_frame_info(driver, &info);
      ++frames;
      bytes += info.encoded_bytes;
      newest = pose_id;
      /* ... here the engine uploads `vertices` to the GPU ... */
    }
    sleep_seconds(1.0 / args.rate);
  }

  /* 4. Close what was opened: the stream, the session if we made it. */
  if ((rc = filigree_driver_close(driver)) != FILIGREE_OK) {
    report("close stream", rc, filigree_driver_last_error(driver));
    goto done;
  }
  if (args.mesh && (rc = filigree_close_session(session, NULL)) != FILIGREE_OK) {
    report("close session", rc, filigree_session_last_error(session));
    goto done;
  }
  printf("poses sent        %llu at %.0f Hz\n", (unsigned long long)last_pose, args.rate);
  printf("frames received   %llu (newest answers pose %llu)\n", (unsigned long long)frames,
         (unsigned long long)newest);
  printf("bytes per frame   %.0f (raw float32 %.0f)\n", frames ? (double)bytes / (double)frames : 0.0,
         12.0 * (double)n);
  status = frames > 0 ? 0 : 1;
  if (frames == 0) fprintf(stderr, "engine_loop_c: no frames received\n");

done:
  filigree_driver_free(driver);
  filigree_session_free(session);
  filigree_client_free(client);
  free(base);
  free(pose);
  free(vertices);
  return status;
}
