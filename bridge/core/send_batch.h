/* One system call for a message's writes to every client: io_uring, without liburing.

Why: each write to a client's socket wakes that client's reader, and on return from the
write the woken reader may take the CPU from the writer. With 32 clients and a busy machine
the writer then waited behind a CPU-bound process for up to a tick, now and then, in the
middle of a message (README, "On a busy machine"). Inside one io_uring_enter the kernel
does not switch (PREEMPT_NONE and PREEMPT_VOLUNTARY, the usual distribution kernels), so
every client has the message before any reader runs.

Each write is a non-blocking sendmsg (MSG_DONTWAIT): it completes inside the call, with the
same result a sendmsg would have given. Where io_uring is not there (Linux before 5.1, a
seccomp profile that forbids it, kernel.io_uring_disabled), send_batch_open fails and the
caller writes one socket at a time. */

#ifndef SEND_BATCH_H
#define SEND_BATCH_H

#include <errno.h>
#include <linux/io_uring.h>
#include <stdint.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/socket.h>
#include <sys/syscall.h>
#include <unistd.h>

#define SEND_BATCH_ENTRIES 64u

typedef struct {
    int ring_fd; /* -1: not open */
    unsigned *sq_tail, *sq_mask, *sq_array;
    unsigned *cq_head, *cq_tail, *cq_mask;
    struct io_uring_sqe *sqes;
    struct io_uring_cqe *cqes;
    void *sq_map, *cq_map;
    size_t sq_map_size, cq_map_size, sqes_size;
} send_batch_t;

static void send_batch_close(send_batch_t *b) {
    if (b->ring_fd < 0) return;
    if (b->sqes != NULL && b->sqes != MAP_FAILED) munmap(b->sqes, b->sqes_size);
    if (b->cq_map != NULL && b->cq_map != MAP_FAILED && b->cq_map != b->sq_map)
        munmap(b->cq_map, b->cq_map_size);
    if (b->sq_map != NULL && b->sq_map != MAP_FAILED) munmap(b->sq_map, b->sq_map_size);
    close(b->ring_fd);
    b->ring_fd = -1;
}

/* 0, or -errno: then the caller writes one socket at a time. */
static int send_batch_open(send_batch_t *b) {
    struct io_uring_params p;
    memset(b, 0, sizeof(*b));
    memset(&p, 0, sizeof(p));
    b->ring_fd = (int)syscall(__NR_io_uring_setup, SEND_BATCH_ENTRIES, &p);
    if (b->ring_fd < 0) {
        int error = errno;
        b->ring_fd = -1;
        return -error;
    }
    b->sq_map_size = p.sq_off.array + p.sq_entries * sizeof(unsigned);
    b->cq_map_size = p.cq_off.cqes + p.cq_entries * sizeof(struct io_uring_cqe);
    if (p.features & IORING_FEAT_SINGLE_MMAP) {
        if (b->cq_map_size > b->sq_map_size) b->sq_map_size = b->cq_map_size;
    }
    b->sq_map = mmap(NULL, b->sq_map_size, PROT_READ | PROT_WRITE, MAP_SHARED | MAP_POPULATE,
                     b->ring_fd, IORING_OFF_SQ_RING);
    if (b->sq_map == MAP_FAILED) goto failed;
    if (p.features & IORING_FEAT_SINGLE_MMAP) {
        b->cq_map = b->sq_map;
    } else {
        b->cq_map = mmap(NULL, b->cq_map_size, PROT_READ | PROT_WRITE,
                         MAP_SHARED | MAP_POPULATE, b->ring_fd, IORING_OFF_CQ_RING);
        if (b->cq_map == MAP_FAILED) goto failed;
    }
    b->sqes_size = p.sq_entries * sizeof(struct io_uring_sqe);
    b->sqes = mmap(NULL, b->sqes_size, PROT_READ | PROT_WRITE, MAP_SHARED | MAP_POPULATE,
                   b->ring_fd, IORING_OFF_SQES);
    if (b->sqes == MAP_FAILED) goto failed;
    b->sq_tail = (unsigned *)((char *)b->sq_map + p.sq_off.tail);
    b->sq_mask = (unsigned *)((char *)b->sq_map + p.sq_off.ring_mask);
    b->sq_array = (unsigned *)((char *)b->sq_map + p.sq_off.array);
    b->cq_head = (unsigned *)((char *)b->cq_map + p.cq_off.head);
    b->cq_tail = (unsigned *)((char *)b->cq_map + p.cq_off.tail);
    b->cq_mask = (unsigned *)((char *)b->cq_map + p.cq_off.ring_mask);
    b->cqes = (struct io_uring_cqe *)((char *)b->cq_map + p.cq_off.cqes);
    return 0;
failed: {
        int error = errno;
        send_batch_close(b);
        return -error;
    }
}

/* sendmsg(fds[i], &messages[i], MSG_DONTWAIT | MSG_NOSIGNAL) for i < count, in calls of
   up to SEND_BATCH_ENTRIES; results[i]: the bytes sent, or -errno. 0, or -errno when the
   ring itself failed: then every write the kernel completed still has its own result
   (a partly written frame must not be written again whole), the others -errno, and the
   caller closes the ring (what it did not take must never be submitted later). */
static int send_batch_run(send_batch_t *b, int count, const int *fds,
                          struct msghdr *messages, int *results) {
    int done = 0, error = 0;
    while (done < count && error == 0) {
        unsigned n = (unsigned)(count - done);
        unsigned tail, i, head, left, ready;
        if (n > SEND_BATCH_ENTRIES) n = SEND_BATCH_ENTRIES;
        tail = *b->sq_tail; /* only this thread writes it */
        for (i = 0; i < n; i++) {
            unsigned index = (tail + i) & *b->sq_mask;
            struct io_uring_sqe *sqe = &b->sqes[index];
            memset(sqe, 0, sizeof(*sqe));
            sqe->opcode = IORING_OP_SENDMSG;
            sqe->fd = fds[done + (int)i];
            sqe->addr = (uint64_t)(uintptr_t)&messages[done + (int)i];
            sqe->len = 1;
            /* MSG_DONTWAIT: a full socket completes at once with -EAGAIN, as sendmsg
               would, rather than waiting in the ring until it drains. */
            sqe->msg_flags = MSG_DONTWAIT | MSG_NOSIGNAL;
            sqe->user_data = (uint64_t)(done + (int)i);
            b->sq_array[index] = index;
        }
        __atomic_store_n(b->sq_tail, tail + n, __ATOMIC_RELEASE);
        /* Non-blocking writes complete within the call that submits them; a signal may
           end the call before it submits (EINTR): then call again. */
        left = n;
        head = *b->cq_head;
        for (;;) {
            long entered;
            ready = __atomic_load_n(b->cq_tail, __ATOMIC_ACQUIRE) - head;
            if (left == 0 && ready >= n) break;
            entered = syscall(__NR_io_uring_enter, b->ring_fd, left, n, IORING_ENTER_GETEVENTS,
                              NULL, 0);
            if (entered < 0 && errno == EINTR) continue;
            if (entered < 0 || (entered == 0 && left > 0)) { /* failed, or took none: no spin */
                error = entered < 0 ? errno : EIO;
                break;
            }
            left -= (unsigned)entered;
        }
        ready = __atomic_load_n(b->cq_tail, __ATOMIC_ACQUIRE) - head;
        for (i = 0; i < n; i++) results[done + (int)i] = -(error ? error : EIO);
        for (i = 0; i < ready; i++, head++) {
            struct io_uring_cqe *cqe = &b->cqes[head & *b->cq_mask];
            if (cqe->user_data < (uint64_t)count) results[cqe->user_data] = cqe->res;
        }
        __atomic_store_n(b->cq_head, head, __ATOMIC_RELEASE);
        done += (int)n;
    }
    for (; done < count; done++) results[done] = -error;
    return -error;
}

#endif
