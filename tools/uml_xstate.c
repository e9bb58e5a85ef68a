/* LD_PRELOAD shim for Debian bookworm's user-mode Linux (6.1) on a host whose XSAVE
 * state is larger than the part UML keeps per task (the legacy area, the header and
 * AVX: 832 bytes), e.g. with AVX-512 or AMX.
 *
 * UML saves and restores a guest task's FP state with PTRACE_GETREGSET and
 * PTRACE_SETREGSET (NT_X86_XSTATE) on a buffer of that size. The host kernel takes a
 * SETREGSET only of the whole XSAVE buffer (else EFAULT), so UML's init dies at its
 * first context switch: "userspace - ptrace set fp regs failed, errno = 14", then
 * "Attempted to kill init! exitcode=0x0000000b". Upstream UML sizes the buffer at run
 * time since 6.13; Debian bookworm's is 6.1.
 *
 * Here each GETREGSET reads the whole buffer, hands UML its part and keeps the rest,
 * keyed by UML's buffer (one per guest task); each SETREGSET puts the two back
 * together, so every task gets its whole state back (AVX-512 registers included). A
 * call whose buffer is whole already, and every other request, passes through.
 * tools/uml_vcan.py builds this with the host's gcc and preloads it into linux.uml.
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <elf.h>
#include <errno.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <sys/ptrace.h>
#include <sys/types.h>
#include <sys/uio.h>

#define WHOLE_MAX (64 * 1024) /* bytes: more than any XSAVE layout (AMX's is 11 KiB) */
#define SLOTS 8192            /* kept rests; UML has far fewer tasks */

typedef long (*ptrace_fn)(enum __ptrace_request, ...);

struct rest {
	const void *part; /* UML's buffer for the task */
	size_t size;
	unsigned char *bytes;
};

static struct rest rests[SLOTS];
static unsigned char whole[WHOLE_MAX];
static pthread_mutex_t lock = PTHREAD_MUTEX_INITIALIZER;

static ptrace_fn real_ptrace(void)
{
	static ptrace_fn real;
	if (!real)
		real = (ptrace_fn)dlsym(RTLD_NEXT, "ptrace");
	return real;
}

/* The slot of UML's buffer ``part``: its own, else a free one; NULL when all are taken. */
static struct rest *slot(const void *part)
{
	size_t start = ((uintptr_t)part >> 4) % SLOTS;
	for (size_t i = 0; i < SLOTS; i++) {
		struct rest *r = &rests[(start + i) % SLOTS];
		if (r->part == part || r->part == NULL)
			return r;
	}
	return NULL;
}

static void keep(const void *part, const unsigned char *bytes, size_t size)
{
	struct rest *r = slot(part);
	if (!r)
		return; /* not kept: the SETREGSET keeps what the task has then */
	if (r->size != size) {
		unsigned char *grown = realloc(r->bytes, size);
		if (!grown)
			return;
		r->bytes = grown;
		r->size = size;
	}
	r->part = part;
	memcpy(r->bytes, bytes, size);
}

static long xstate(int request, pid_t pid, void *addr, struct iovec *part)
{
	ptrace_fn real = real_ptrace();
	struct iovec all = {whole, WHOLE_MAX};
	long done;

	pthread_mutex_lock(&lock);
	if (real(PTRACE_GETREGSET, pid, addr, &all) != 0 || part->iov_len >= all.iov_len) {
		pthread_mutex_unlock(&lock);
		return real(request, pid, addr, part); /* whole already, or not readable: as asked */
	}
	if (request == PTRACE_GETREGSET) {
		memcpy(part->iov_base, whole, part->iov_len);
		keep(part->iov_base, whole + part->iov_len, all.iov_len - part->iov_len);
		done = 0;
	} else {
		struct rest *r = slot(part->iov_base);
		if (r && r->part == part->iov_base && r->size == all.iov_len - part->iov_len)
			memcpy(whole + part->iov_len, r->bytes, r->size);
		memcpy(whole, part->iov_base, part->iov_len);
		done = real(PTRACE_SETREGSET, pid, addr, &all);
	}
	int saved = errno;
	pthread_mutex_unlock(&lock);
	errno = saved;
	return done;
}

long ptrace(enum __ptrace_request request, ...)
{
	va_list args;
	va_start(args, request);
	pid_t pid = va_arg(args, pid_t);
	void *addr = va_arg(args, void *);
	void *data = va_arg(args, void *);
	va_end(args);
	if ((request == PTRACE_GETREGSET || request == PTRACE_SETREGSET) && (uintptr_t)addr == NT_X86_XSTATE)
		return xstate(request, pid, addr, data);
	return real_ptrace()(request, pid, addr, data);
}
