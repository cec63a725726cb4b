# cython: language_level=3
"""Serialized messages of rcl subscriptions, waited for and taken with the interpreter's lock
released.

rclpy takes a raw message holding the lock: a peer's 10 MB TFMessage kept every other
thread of the daemon (the event loop among them) waiting about 20 ms. Here rcl's own wait set
and `rcl_take_serialized_message` run without it; the caller reads the message from a view on
this reader's buffer, valid until its next `take`.

Built by setup.py where rcl's headers are found beside the interpreter (ROS 2 from PyPI puts
them under ``sys.prefix/include``); imported only after rclpy, which has loaded the rcl
libraries this module needs. Elsewhere the daemon takes /tf through rclpy, as before.
"""

from cpython.bytes cimport PyBytes_FromStringAndSize
from cpython.memoryview cimport PyMemoryView_FromMemory
from cpython.buffer cimport PyBUF_READ
from libc.stdint cimport int64_t, uint8_t
from libc.stdlib cimport calloc, free

# Bump with `bridge.ros.raw_reader.READER_INTERFACE`: a module from an older build is not used.
INTERFACE = 2


cdef extern from "rcl/rcl.h" nogil:
    ctypedef int rcl_ret_t
    ctypedef struct rcl_allocator_t:
        pass
    ctypedef struct rcl_context_t:
        pass
    ctypedef struct rcl_subscription_t:
        pass
    ctypedef struct rcl_guard_condition_t:
        pass
    ctypedef struct rmw_message_info_t:
        pass
    ctypedef struct rmw_subscription_allocation_t:
        pass
    ctypedef struct rcl_serialized_message_t:
        uint8_t *buffer
        size_t buffer_length
    ctypedef struct rcl_wait_set_t:
        const rcl_subscription_t **subscriptions
        size_t size_of_subscriptions
        const rcl_guard_condition_t **guard_conditions
        size_t size_of_guard_conditions

    enum:
        RCL_RET_OK
        RCL_RET_TIMEOUT
        RCL_RET_SUBSCRIPTION_TAKE_FAILED

    rcl_allocator_t rcl_get_default_allocator()
    rcl_wait_set_t rcl_get_zero_initialized_wait_set()
    rcl_ret_t rcl_wait_set_init(rcl_wait_set_t *wait_set, size_t subscriptions,
                                size_t guard_conditions, size_t timers, size_t clients,
                                size_t services, size_t events, rcl_context_t *context,
                                rcl_allocator_t allocator)
    rcl_ret_t rcl_wait_set_fini(rcl_wait_set_t *wait_set)
    rcl_ret_t rcl_wait_set_resize(rcl_wait_set_t *wait_set, size_t subscriptions,
                                  size_t guard_conditions, size_t timers, size_t clients,
                                  size_t services, size_t events)
    rcl_ret_t rcl_wait_set_clear(rcl_wait_set_t *wait_set)
    rcl_ret_t rcl_wait_set_add_subscription(rcl_wait_set_t *wait_set,
                                            const rcl_subscription_t *subscription,
                                            size_t *index)
    rcl_ret_t rcl_wait_set_add_guard_condition(rcl_wait_set_t *wait_set,
                                               const rcl_guard_condition_t *condition,
                                               size_t *index)
    rcl_ret_t rcl_wait(rcl_wait_set_t *wait_set, int64_t timeout)
    rcl_ret_t rcl_take_serialized_message(const rcl_subscription_t *subscription,
                                          rcl_serialized_message_t *message,
                                          rmw_message_info_t *info,
                                          rmw_subscription_allocation_t *allocation)
    rcl_serialized_message_t rmw_get_zero_initialized_serialized_message()
    rcl_ret_t rmw_serialized_message_init(rcl_serialized_message_t *message, size_t capacity,
                                          const rcl_allocator_t *allocator)
    rcl_ret_t rmw_serialized_message_fini(rcl_serialized_message_t *message)


cdef extern from "rcutils/error_handling.h" nogil:
    void rcutils_reset_error()


class ReaderError(RuntimeError):
    """rcl refused a wait set or a take: the reader can go on no further."""


cdef class RawReader:
    """Takes serialized messages of ``subscriptions`` (rclpy's `_rclpy.Subscription`
    handles, which the caller keeps alive and destroys after `close`) in turn, waiting
    for them (and for ``wake``, an `_rclpy.GuardCondition`, which ends a wait) without the
    interpreter's lock. One thread calls `take`; any thread may trigger ``wake``."""

    cdef rcl_wait_set_t _wait_set
    cdef rcl_serialized_message_t _message
    cdef rcl_allocator_t _allocator
    cdef const rcl_subscription_t **_subscriptions
    cdef size_t _count
    cdef size_t _next
    cdef const rcl_guard_condition_t *_wake
    cdef bint _open

    def __cinit__(self, context, subscriptions, wake):
        cdef rcl_ret_t ret
        self._open = False
        self._count = len(subscriptions)
        self._subscriptions = _pointers(subscriptions)
        self._wake = <const rcl_guard_condition_t *><size_t>wake.pointer
        self._allocator = rcl_get_default_allocator()
        self._wait_set = rcl_get_zero_initialized_wait_set()
        if rcl_wait_set_init(&self._wait_set, self._count, 1, 0, 0, 0, 0,
                             <rcl_context_t *><size_t>context.pointer,
                             self._allocator) != RCL_RET_OK:
            rcutils_reset_error()
            raise ReaderError("rcl_wait_set_init failed")
        self._message = rmw_get_zero_initialized_serialized_message()
        if rmw_serialized_message_init(&self._message, 0, &self._allocator) != RCL_RET_OK:
            rcutils_reset_error()
            ret = rcl_wait_set_fini(&self._wait_set)
            raise ReaderError("rmw_serialized_message_init failed")
        self._next = 0
        self._open = True

    def take(self, double timeout_s):
        """``(index, view)``: the next message of subscription ``index``, as a read-only
        view valid until the next call; None when ``timeout_s`` passed or ``wake`` was
        triggered with nothing to take. Subscriptions take turns, so a busy one cannot
        starve the others."""
        cdef rcl_ret_t ret = RCL_RET_SUBSCRIPTION_TAKE_FAILED
        cdef rmw_message_info_t info
        cdef size_t tried, index = 0
        cdef int64_t timeout_ns = <int64_t>(timeout_s * 1e9)
        cdef bint waited = False
        if not self._open:
            raise ReaderError("the reader is closed")
        with nogil:
            while True:
                tried = 0
                while tried < self._count:
                    index = (self._next + tried) % self._count
                    ret = rcl_take_serialized_message(self._subscriptions[index],
                                                      &self._message, &info, NULL)
                    if ret == RCL_RET_OK:
                        break
                    if ret != RCL_RET_SUBSCRIPTION_TAKE_FAILED:
                        break
                    tried += 1
                if ret == RCL_RET_OK or ret != RCL_RET_SUBSCRIPTION_TAKE_FAILED or waited:
                    break
                ret = self._wait(timeout_ns)
                if ret != RCL_RET_OK:
                    break
                waited = True
                ret = RCL_RET_SUBSCRIPTION_TAKE_FAILED
        if ret == RCL_RET_OK:
            self._next = (index + 1) % self._count
            return index, PyMemoryView_FromMemory(<char *>self._message.buffer,
                                                  <Py_ssize_t>self._message.buffer_length,
                                                  PyBUF_READ)
        if ret == RCL_RET_TIMEOUT or ret == RCL_RET_SUBSCRIPTION_TAKE_FAILED:
            return None
        rcutils_reset_error()
        raise ReaderError(f"rcl returned {ret} while waiting for or taking a message")

    def set_subscriptions(self, subscriptions):
        """Take ``subscriptions`` (any number, none too) from now on, in place of those
        before. Called by the thread that calls `take`, between two takes."""
        if not self._open:
            raise ReaderError("the reader is closed")
        cdef size_t count = len(subscriptions)
        cdef const rcl_subscription_t **pointers = _pointers(subscriptions)
        if rcl_wait_set_resize(&self._wait_set, count, 1, 0, 0, 0, 0) != RCL_RET_OK:
            free(pointers)
            rcutils_reset_error()
            raise ReaderError("rcl_wait_set_resize failed")
        free(self._subscriptions)
        self._subscriptions = pointers
        self._count = count
        self._next = 0

    def take_more(self, size_t index, size_t max_count, size_t max_bytes):
        """The messages of subscription ``index`` already waiting, in order, each copied
        to bytes, without waiting: at most ``max_count``, and none after the one that
        brings the total to ``max_bytes``. The view `take` gave is invalid afterwards."""
        cdef rcl_ret_t ret = RCL_RET_OK
        cdef rmw_message_info_t info
        cdef size_t total = 0
        if not self._open:
            raise ReaderError("the reader is closed")
        if index >= self._count:
            raise IndexError(f"index: expected below {self._count}, got {index}")
        taken = []
        while <size_t>len(taken) < max_count and total < max_bytes:
            with nogil:
                ret = rcl_take_serialized_message(self._subscriptions[index], &self._message,
                                                  &info, NULL)
            if ret != RCL_RET_OK:
                break
            total += self._message.buffer_length
            taken.append(PyBytes_FromStringAndSize(<char *>self._message.buffer,
                                                   <Py_ssize_t>self._message.buffer_length))
        if ret != RCL_RET_OK and ret != RCL_RET_SUBSCRIPTION_TAKE_FAILED:
            rcutils_reset_error()
            raise ReaderError(f"rcl returned {ret} while taking a message")
        return taken

    cdef rcl_ret_t _wait(self, int64_t timeout_ns) noexcept nogil:
        cdef size_t i
        cdef rcl_ret_t ret = rcl_wait_set_clear(&self._wait_set)
        i = 0
        while ret == RCL_RET_OK and i < self._count:
            ret = rcl_wait_set_add_subscription(&self._wait_set, self._subscriptions[i], NULL)
            i += 1
        if ret == RCL_RET_OK:
            ret = rcl_wait_set_add_guard_condition(&self._wait_set, self._wake, NULL)
        if ret == RCL_RET_OK:
            ret = rcl_wait(&self._wait_set, timeout_ns)
        return ret

    def close(self):
        """Free the wait set and the buffer (the subscriptions are the caller's)."""
        cdef rcl_ret_t ret
        if self._open:
            self._open = False
            ret = rmw_serialized_message_fini(&self._message)
            ret = rcl_wait_set_fini(&self._wait_set)

    def __dealloc__(self):
        self.close()
        if self._subscriptions != NULL:
            free(self._subscriptions)
            self._subscriptions = NULL


cdef const rcl_subscription_t **_pointers(subscriptions) except? NULL:
    """The rcl subscriptions of rclpy's handles, in a new array (NULL for none)."""
    cdef size_t count = len(subscriptions)
    if count == 0:
        return NULL
    cdef const rcl_subscription_t **pointers = <const rcl_subscription_t **>calloc(
        count, sizeof(rcl_subscription_t *))
    if pointers == NULL:
        raise MemoryError()
    try:
        for i, subscription in enumerate(subscriptions):
            pointers[i] = <const rcl_subscription_t *><size_t>subscription.pointer
    except BaseException:
        free(pointers)
        raise
    return pointers
