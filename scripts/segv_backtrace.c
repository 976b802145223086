// A native backtrace on a crash, for machines without a debugger (the GPU machines have no gdb):
//   cc -shared -fPIC -O1 -o segv_backtrace.so scripts/segv_backtrace.c
//   LD_PRELOAD=$PWD/segv_backtrace.so python -m pytest ...
// On SIGSEGV, SIGBUS or SIGFPE it writes the frames (module + offset, and the symbol where it is
// exported) to stderr, then dies of the signal as it would have. Python's faulthandler, installed
// later, prints the Python frames first and then hands the signal on to this handler.
#define _GNU_SOURCE
#include <execinfo.h>
#include <signal.h>
#include <string.h>
#include <unistd.h>

static void on_crash(int sig) {
  void* frames[64];
  const int n = backtrace(frames, 64);
  static const char header[] = "\n--- native backtrace (segv_backtrace.so) ---\n";
  (void)!write(STDERR_FILENO, header, sizeof header - 1);
  backtrace_symbols_fd(frames, n, STDERR_FILENO);
  signal(sig, SIG_DFL);
  raise(sig);
}

// Exported too: call it again (ctypes) where a later library has replaced the handler.
__attribute__((constructor)) void segv_backtrace_install(void) {
  void* warm[1];
  backtrace(warm, 1);  // loads libgcc's unwinder now, not inside the handler
  struct sigaction action;
  memset(&action, 0, sizeof action);
  action.sa_handler = on_crash;
  sigemptyset(&action.sa_mask);
  sigaction(SIGSEGV, &action, NULL);
  sigaction(SIGBUS, &action, NULL);
  sigaction(SIGFPE, &action, NULL);
}
