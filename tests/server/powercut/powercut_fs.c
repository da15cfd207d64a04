/*
 * powercut_fs: a FUSE 3 passthrough filesystem that can lose power.
 *
 *   powercut_fs [--fsync_delay_ms N] [--cut_in_fsync_of NAME] [--lying_fsync_of NAME]
 *               BACKING_DIR MOUNTPOINT
 *
 * It mirrors BACKING_DIR at MOUNTPOINT (high-level libfuse API, one thread,
 * in the foreground) and remembers, for every regular file, what its data
 * was when it was last made durable. On a signal the power goes:
 *
 *   SIGUSR1  "drop":  every file's data reverts to its durable data: all
 *            writes and truncations since the file's last fsync/fdatasync
 *            are undone, exactly.
 *   SIGUSR2  "torn":  the same, except that the first half (rounded down)
 *            of what was written past a file's durable end survives, like a
 *            disk that got part of an append to the platter: a torn tail.
 *
 * When the power goes is either the signal itself, or, with
 * --cut_in_fsync_of NAME, the next fsync/fdatasync of a file named NAME
 * (its last path component) that has data not durable yet: the cut then
 * happens inside that fsync, which never completes (the caller stays
 * blocked, as behind a dead disk, until it is killed or the filesystem
 * ends with SIGTERM; it then gets EIO). That makes "data written, not yet
 * durable" certain at the cut instead of likely.
 *
 * At the cut the filesystem stops answering (an operation still queued
 * gets EIO or, once unmounted, ENOTCONN), reverts the files in
 * BACKING_DIR and prints one line on stdout
 *
 *   powercut: mode=drop files=F unsynced_write_bytes=W size_bytes_dropped=D restored_bytes=R kept_torn_bytes=K
 *
 * (F files had data that was not durable; W bytes were written to them by
 * write(2) since their last fsync; D bytes were cut off their ends; R bytes
 * inside their durable part were put back after being overwritten; K bytes
 * of torn tail were kept). A cut on the signal then unmounts and exits 0;
 * a cut inside an fsync waits for SIGTERM to unmount and exit 0.
 * SIGTERM/SIGINT/SIGHUP or an unmount without a cut end it normally:
 * nothing reverted, "powercut: mode=none ...", exit 0 (exit 1 when a cut
 * was asked for but no matching fsync came). Mount again on the same
 * BACKING_DIR to see what survived.
 *
 * What it models:
 * - File DATA is durable only after fsync(2) or fdatasync(2) on the file
 *   (any descriptor of the same inode; both are treated alike), or after a
 *   write through a descriptor opened with O_SYNC/O_DSYNC. close(2),
 *   flush and unmount make nothing durable. Reads see the latest data (a
 *   page cache).
 * - Files the filesystem has not written to since it was mounted are
 *   durable as they are (a new mount starts from what survived).
 * - --lying_fsync_of NAME: a lying disk for files named NAME: their fsyncs
 *   answer success and make nothing durable (to show that a test over this
 *   filesystem fails when fsync is not really there).
 * - --fsync_delay_ms makes every fsync take that long before it counts, so
 *   a cut is likely to land while data is written but not yet durable; a
 *   cut during the delay fails that fsync (EIO) and it does not count.
 *
 * What it does NOT model (said plainly, so nobody reads more into a pass):
 * - Metadata is durable at once: create, mkdir, rename, unlink, rmdir,
 *   chmod, utimens happen in BACKING_DIR when asked, and a cut does not
 *   undo them; an fsync of a directory does nothing. (A real filesystem may
 *   lose a rename or a new file that was not followed by an fsync of its
 *   directory; a file created but never fsynced is here empty, not gone.)
 * - Within a file, no reordering or partial survival of un-fsynced data
 *   other than the torn tail above; no corruption of durable data; sizes
 *   and data revert together.
 * - No mmap-specific handling (shared writable mappings reach it as
 *   writes), no fallocate, no hard links, no xattrs, no special files.
 * - Timestamps and permissions are not reverted.
 *
 * Build: cc -Wall -O2 powercut_fs.c $(pkg-config --cflags --libs fuse3)
 */
#define FUSE_USE_VERSION 31
#define _GNU_SOURCE

#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <fuse.h>
#include <fuse_lowlevel.h>
#include <signal.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/statvfs.h>
#include <sys/types.h>
#include <time.h>
#include <unistd.h>

/* ---- Durable state of dirty files ---------------------------------------
 * A file with no node is clean: its bytes in BACKING_DIR are durable. The
 * first write or truncation after a mount or an fsync makes a node that
 * remembers the durable size and, before each later change, the durable
 * bytes the change overwrites (an undo log). An fsync frees the node: the
 * current bytes become the durable ones. A cut applies every undo log
 * backwards and truncates each file to its durable size. */

struct undo {
  off_t off;
  size_t len;
  char *bytes;
};

struct node {
  dev_t dev;
  ino_t ino;
  int fd; /* our own O_RDWR descriptor of the inode (survives rename/unlink) */
  off_t durable_size;
  struct undo *undo;
  size_t n_undo, cap_undo;
  uint64_t unsynced_write_bytes;
  struct node *next;
};

static struct node *g_nodes;
static int g_backing = -1;                   /* O_DIRECTORY descriptor of BACKING_DIR */
static long g_fsync_delay_ms;
static const char *g_cut_in_fsync_of;        /* --cut_in_fsync_of NAME, or NULL */
static const char *g_lying_fsync_of;         /* --lying_fsync_of NAME, or NULL */
static volatile sig_atomic_t g_cut_asked;    /* 0, SIGUSR1 (drop) or SIGUSR2 (torn) */
static volatile sig_atomic_t g_cut;          /* set once the power has gone */
static struct fuse_session *g_session;

static const char *rel(const char *path) { /* "/a/b" -> "a/b", "/" -> "." */
  while (*path == '/') ++path;
  return *path ? path : ".";
}

static struct node *find_node(const struct stat *st) {
  for (struct node *n = g_nodes; n; n = n->next)
    if (n->dev == st->st_dev && n->ino == st->st_ino) return n;
  return NULL;
}

/* The node of the file behind `fd` (or `path` when fd < 0), made when the
 * file is clean. Returns -errno on failure. */
static int dirty_node(const char *path, int fd, struct node **out) {
  struct stat st;
  if ((fd >= 0 ? fstat(fd, &st) : fstatat(g_backing, rel(path), &st, AT_SYMLINK_NOFOLLOW)) != 0)
    return -errno;
  if (!S_ISREG(st.st_mode)) return -EINVAL;
  struct node *n = find_node(&st);
  if (!n) {
    char proc[64];
    int own;
    if (fd >= 0) {
      snprintf(proc, sizeof proc, "/proc/self/fd/%d", fd);
      own = open(proc, O_RDWR | O_CLOEXEC);
    } else {
      own = openat(g_backing, rel(path), O_RDWR | O_CLOEXEC | O_NOFOLLOW);
    }
    if (own < 0) return -errno;
    n = calloc(1, sizeof *n);
    if (!n) {
      close(own);
      return -ENOMEM;
    }
    n->dev = st.st_dev;
    n->ino = st.st_ino;
    n->fd = own;
    n->durable_size = st.st_size;
    n->next = g_nodes;
    g_nodes = n;
  }
  *out = n;
  return 0;
}

/* Remembers the durable bytes of [off, off+len) before they change. */
static int save_undo(struct node *n, off_t off, off_t len) {
  if (off >= n->durable_size || len <= 0) return 0;
  if (off + len > n->durable_size) len = n->durable_size - off;
  char *bytes = malloc(len);
  if (!bytes) return -ENOMEM;
  ssize_t got = pread(n->fd, bytes, len, off);
  if (got < 0) {
    free(bytes);
    return -errno;
  }
  /* Bytes past the current end (after a shrink) read as absent: those are
   * covered by the shrink's own undo record, applied later in the reverse
   * order. */
  if (got == 0) {
    free(bytes);
    return 0;
  }
  if (n->n_undo == n->cap_undo) {
    size_t cap = n->cap_undo ? 2 * n->cap_undo : 16;
    struct undo *u = realloc(n->undo, cap * sizeof *u);
    if (!u) {
      free(bytes);
      return -ENOMEM;
    }
    n->undo = u;
    n->cap_undo = cap;
  }
  n->undo[n->n_undo++] = (struct undo){off, (size_t)got, bytes};
  return 0;
}

static void free_node(struct node *n) {
  for (size_t i = 0; i < n->n_undo; ++i) free(n->undo[i].bytes);
  free(n->undo);
  close(n->fd);
  free(n);
}

/* The file behind `fd` is durable now: forget its node. */
static void commit(int fd) {
  struct stat st;
  if (fstat(fd, &st) != 0) return;
  for (struct node **p = &g_nodes; *p; p = &(*p)->next) {
    if ((*p)->dev == st.st_dev && (*p)->ino == st.st_ino) {
      struct node *n = *p;
      *p = n->next;
      free_node(n);
      return;
    }
  }
}

/* The power goes: every dirty file back to its durable data. */
static void cut_power(int torn) {
  unsigned long files = 0;
  unsigned long long written = 0, dropped = 0, restored = 0, kept = 0;
  while (g_nodes) {
    struct node *n = g_nodes;
    g_nodes = n->next;
    struct stat st;
    off_t size = fstat(n->fd, &st) == 0 ? st.st_size : n->durable_size;
    for (size_t i = n->n_undo; i-- > 0;) {
      const struct undo *u = &n->undo[i];
      if (pwrite(n->fd, u->bytes, u->len, u->off) != (ssize_t)u->len)
        fprintf(stderr, "powercut_fs: cannot restore %zu bytes: %s\n", u->len, strerror(errno));
      restored += u->len;
    }
    off_t end = n->durable_size;
    if (torn && size > end) {
      kept += (size - end) / 2;
      end += (size - end) / 2;
    }
    if (size > end) dropped += size - end;
    char proc[64], name[4096];
    snprintf(proc, sizeof proc, "/proc/self/fd/%d", n->fd);
    ssize_t len = readlink(proc, name, sizeof name - 1);
    name[len > 0 ? len : 0] = '\0';
    fprintf(stderr, "powercut_fs: %s: %lld bytes -> %lld (durable %lld), %zu overwrites undone\n",
            name, (long long)size, (long long)end, (long long)n->durable_size, n->n_undo);
    if (ftruncate(n->fd, end) != 0)
      fprintf(stderr, "powercut_fs: cannot truncate: %s\n", strerror(errno));
    fsync(n->fd);
    ++files;
    written += n->unsynced_write_bytes;
    free_node(n);
  }
  printf("powercut: mode=%s files=%lu unsynced_write_bytes=%llu size_bytes_dropped=%llu "
         "restored_bytes=%llu kept_torn_bytes=%llu\n",
         torn ? "torn" : "drop", files, written, dropped, restored, kept);
  fflush(stdout);
}

/* ---- Operations ------------------------------------------------------- */

#define CUT_CHECK() \
  do {              \
    if (g_cut) return -EIO; \
  } while (0)

static void *pc_init(struct fuse_conn_info *conn, struct fuse_config *cfg) {
  (void)conn;
  cfg->use_ino = 1;
  cfg->hard_remove = 1; /* unlink really unlinks; open files go on by descriptor */
  cfg->entry_timeout = 0;
  cfg->attr_timeout = 0;
  cfg->negative_timeout = 0;
  return NULL;
}

static int pc_getattr(const char *path, struct stat *st, struct fuse_file_info *fi) {
  CUT_CHECK();
  int rc = fi ? fstat(fi->fh, st) : fstatat(g_backing, rel(path), st, AT_SYMLINK_NOFOLLOW);
  return rc == 0 ? 0 : -errno;
}

static int pc_readdir(const char *path, void *buf, fuse_fill_dir_t filler, off_t off,
                      struct fuse_file_info *fi, enum fuse_readdir_flags flags) {
  (void)off, (void)fi, (void)flags;
  CUT_CHECK();
  int fd = openat(g_backing, rel(path), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) return -errno;
  DIR *d = fdopendir(fd);
  if (!d) {
    int e = errno;
    close(fd);
    return -e;
  }
  struct dirent *e;
  while ((e = readdir(d)) != NULL) {
    struct stat st = {0};
    st.st_ino = e->d_ino;
    st.st_mode = (mode_t)DTTOIF(e->d_type);
    if (filler(buf, e->d_name, &st, 0, 0)) break;
  }
  closedir(d);
  return 0;
}

static int pc_mkdir(const char *path, mode_t mode) {
  CUT_CHECK();
  return mkdirat(g_backing, rel(path), mode) == 0 ? 0 : -errno;
}

static int pc_rmdir(const char *path) {
  CUT_CHECK();
  return unlinkat(g_backing, rel(path), AT_REMOVEDIR) == 0 ? 0 : -errno;
}

static int pc_unlink(const char *path) {
  CUT_CHECK();
  return unlinkat(g_backing, rel(path), 0) == 0 ? 0 : -errno;
}

static int pc_rename(const char *from, const char *to, unsigned int flags) {
  CUT_CHECK();
  if (flags) return -EINVAL;
  return renameat(g_backing, rel(from), g_backing, rel(to)) == 0 ? 0 : -errno;
}

static int pc_chmod(const char *path, mode_t mode, struct fuse_file_info *fi) {
  CUT_CHECK();
  int rc = fi ? fchmod(fi->fh, mode) : fchmodat(g_backing, rel(path), mode, 0);
  return rc == 0 ? 0 : -errno;
}

static int pc_utimens(const char *path, const struct timespec tv[2], struct fuse_file_info *fi) {
  CUT_CHECK();
  int rc = fi ? futimens(fi->fh, tv) : utimensat(g_backing, rel(path), tv, AT_SYMLINK_NOFOLLOW);
  return rc == 0 ? 0 : -errno;
}

static int truncate_file(const char *path, int fd, off_t size) {
  struct node *n;
  int rc = dirty_node(path, fd, &n);
  if (rc) return rc;
  struct stat st;
  if (fstat(n->fd, &st) != 0) return -errno;
  if (size < st.st_size && (rc = save_undo(n, size, st.st_size - size))) return rc;
  return ftruncate(n->fd, size) == 0 ? 0 : -errno;
}

static int pc_truncate(const char *path, off_t size, struct fuse_file_info *fi) {
  CUT_CHECK();
  return truncate_file(path, fi ? (int)fi->fh : -1, size);
}

static int pc_open(const char *path, struct fuse_file_info *fi) {
  CUT_CHECK();
  int flags = fi->flags & ~(O_CREAT | O_EXCL | O_NOCTTY);
  if (flags & O_TRUNC) {
    /* Undoable truncation first, then open without O_TRUNC. */
    int rc = truncate_file(path, -1, 0);
    if (rc) return rc;
    flags &= ~O_TRUNC;
  }
  int fd = openat(g_backing, rel(path), flags | O_CLOEXEC);
  if (fd < 0) return -errno;
  fi->fh = fd;
  return 0;
}

static int pc_create(const char *path, mode_t mode, struct fuse_file_info *fi) {
  CUT_CHECK();
  struct stat st;
  int flags = fi->flags;
  if ((flags & O_TRUNC) && fstatat(g_backing, rel(path), &st, AT_SYMLINK_NOFOLLOW) == 0 &&
      S_ISREG(st.st_mode)) {
    int rc = truncate_file(path, -1, 0);
    if (rc) return rc;
  }
  flags &= ~O_TRUNC; /* a new file is empty anyway (and durably so: metadata is) */
  int fd = openat(g_backing, rel(path), flags | O_CREAT | O_CLOEXEC, mode);
  if (fd < 0) return -errno;
  fi->fh = fd;
  return 0;
}

static int pc_read(const char *path, char *buf, size_t size, off_t off,
                   struct fuse_file_info *fi) {
  (void)path;
  CUT_CHECK();
  ssize_t n = pread(fi->fh, buf, size, off);
  return n < 0 ? -errno : (int)n;
}

static int pc_write(const char *path, const char *buf, size_t size, off_t off,
                    struct fuse_file_info *fi) {
  CUT_CHECK();
  struct node *n;
  int rc = dirty_node(path, fi->fh, &n);
  if (rc) return rc;
  if ((rc = save_undo(n, off, (off_t)size))) return rc;
  ssize_t done = pwrite(fi->fh, buf, size, off);
  if (done < 0) return -errno;
  n->unsynced_write_bytes += (uint64_t)done;
  int fl = fcntl(fi->fh, F_GETFL);
  if (fl >= 0 && (fl & (O_SYNC | O_DSYNC))) commit(fi->fh);
  return (int)done;
}

static int pc_statfs(const char *path, struct statvfs *sv) {
  (void)path;
  CUT_CHECK();
  return fstatvfs(g_backing, sv) == 0 ? 0 : -errno;
}

static int pc_flush(const char *path, struct fuse_file_info *fi) {
  (void)path, (void)fi;
  return 0; /* close(2) makes nothing durable */
}

static int pc_release(const char *path, struct fuse_file_info *fi) {
  (void)path;
  close(fi->fh);
  return 0;
}

static int named(const char *path, const char *name) {
  if (!path || !name) return 0;
  const char *base = strrchr(path, '/');
  return strcmp(base ? base + 1 : path, name) == 0;
}

/* --cut_in_fsync_of: this fsync is the one the power goes in when a cut
 * was asked, the file is named NAME and it has data not durable yet. */
static int cut_here(const char *path, int fd) {
  if (!g_cut_asked || !named(path, g_cut_in_fsync_of)) return 0;
  struct stat st;
  return fstat(fd, &st) == 0 && find_node(&st) != NULL;
}

static int pc_fsync(const char *path, int datasync, struct fuse_file_info *fi) {
  CUT_CHECK();
  if (g_fsync_delay_ms > 0) {
    struct timespec left = {g_fsync_delay_ms / 1000, (g_fsync_delay_ms % 1000) * 1000000L};
    while (nanosleep(&left, &left) != 0 && errno == EINTR) {
      if (g_cut) return -EIO; /* the power went before the disk said done */
      if (g_cut_asked && g_cut_in_fsync_of) break;
    }
  }
  if (cut_here(path, fi->fh)) {
    g_cut = g_cut_asked;
    cut_power(g_cut == SIGUSR2);
    /* A dead disk: this fsync never completes. Nothing else is served
     * meanwhile (one thread); SIGTERM (libfuse's handler) ends the wait. */
    while (!fuse_session_exited(g_session)) {
      struct timespec t = {0, 20 * 1000000L};
      nanosleep(&t, NULL);
    }
    return -EIO;
  }
  if (named(path, g_lying_fsync_of)) return 0;
  if ((datasync ? fdatasync(fi->fh) : fsync(fi->fh)) != 0) return -errno;
  commit(fi->fh);
  return 0;
}

static int pc_fsyncdir(const char *path, int datasync, struct fuse_file_info *fi) {
  (void)path, (void)datasync, (void)fi;
  CUT_CHECK();
  return 0; /* metadata is durable at once (see the header) */
}

static const struct fuse_operations ops = {
    .init = pc_init,
    .getattr = pc_getattr,
    .readdir = pc_readdir,
    .mkdir = pc_mkdir,
    .rmdir = pc_rmdir,
    .unlink = pc_unlink,
    .rename = pc_rename,
    .chmod = pc_chmod,
    .utimens = pc_utimens,
    .truncate = pc_truncate,
    .open = pc_open,
    .create = pc_create,
    .read = pc_read,
    .write = pc_write,
    .statfs = pc_statfs,
    .flush = pc_flush,
    .release = pc_release,
    .fsync = pc_fsync,
    .fsyncdir = pc_fsyncdir,
};

static void on_cut(int sig) {
  g_cut_asked = sig;
  if (g_cut_in_fsync_of) return; /* the next matching fsync cuts */
  g_cut = sig;
  if (g_session) fuse_session_exit(g_session);
}

int main(int argc, char **argv) {
  int i = 1;
  for (; i + 1 < argc && strncmp(argv[i], "--", 2) == 0; i += 2) {
    if (strcmp(argv[i], "--fsync_delay_ms") == 0) {
      g_fsync_delay_ms = atol(argv[i + 1]);
    } else if (strcmp(argv[i], "--cut_in_fsync_of") == 0) {
      g_cut_in_fsync_of = argv[i + 1];
    } else if (strcmp(argv[i], "--lying_fsync_of") == 0) {
      g_lying_fsync_of = argv[i + 1];
    } else {
      break;
    }
  }
  if (argc - i != 2) {
    fprintf(stderr,
            "usage: %s [--fsync_delay_ms N] [--cut_in_fsync_of NAME] [--lying_fsync_of NAME] "
            "BACKING_DIR MOUNTPOINT\n",
            argv[0]);
    return 2;
  }
  const char *backing = argv[i], *mountpoint = argv[i + 1];
  g_backing = open(backing, O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (g_backing < 0) {
    fprintf(stderr, "powercut_fs: cannot open %s: %s\n", backing, strerror(errno));
    return 2;
  }
  char *fuse_argv[] = {argv[0], "-o", "fsname=powercut,subtype=powercut", NULL};
  struct fuse_args args = FUSE_ARGS_INIT(3, fuse_argv);
  struct fuse *f = fuse_new(&args, &ops, sizeof ops, NULL);
  if (!f) return 2;
  if (fuse_mount(f, mountpoint) != 0) {
    fprintf(stderr, "powercut_fs: cannot mount on %s\n", mountpoint);
    fuse_destroy(f);
    return 2;
  }
  g_session = fuse_get_session(f);
  if (fuse_set_signal_handlers(g_session) != 0) return 2;
  struct sigaction sa;
  memset(&sa, 0, sizeof sa);
  sa.sa_handler = on_cut;
  sigemptyset(&sa.sa_mask);
  sa.sa_flags = 0; /* no SA_RESTART: the read of /dev/fuse and fsync's delay return EINTR */
  sigaction(SIGUSR1, &sa, NULL);
  sigaction(SIGUSR2, &sa, NULL);
  fprintf(stderr, "powercut_fs: %s on %s, fsync delay %ld ms\n", backing, mountpoint,
          g_fsync_delay_ms);
  int rc = fuse_loop(f);
  fuse_remove_signal_handlers(g_session);
  if (g_cut && !g_cut_in_fsync_of) {
    cut_power(g_cut == SIGUSR2);
  } else if (!g_cut) {
    unsigned long dirty = 0;
    for (struct node *n = g_nodes; n; n = n->next) ++dirty;
    printf("powercut: mode=none files=%lu (not reverted)%s\n", dirty,
           g_cut_asked ? "; a cut was asked but no matching fsync came" : "");
    fflush(stdout);
  }
  fuse_unmount(f);
  fuse_destroy(f);
  /* fuse_loop gives the number of the signal that ended it (>0) or -errno. */
  return rc < 0 || (g_cut_asked && !g_cut) ? 1 : 0;
}
