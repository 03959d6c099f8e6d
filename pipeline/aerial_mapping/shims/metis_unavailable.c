/* Debian ships METIS only as a shared library, and CHOLMOD's static archive (linked into the static
 * role binaries through Ceres) references two of its functions from its graph-partition module. The pose
 * graph configures Ceres for AMD ordering and Eigen's sparse Cholesky, so neither is ever called; if one
 * were, CHOLMOD gets METIS_ERROR (-4) and reports a failed ordering rather than crashing the robot. */
#include <stdint.h>

typedef int32_t idx_t;
enum { kMetisError = -4 };

int METIS_NodeND(idx_t* nvtxs, idx_t* xadj, idx_t* adjncy, idx_t* vwgt, idx_t* options, idx_t* perm, idx_t* iperm);
int METIS_ComputeVertexSeparator(idx_t* nvtxs, idx_t* xadj, idx_t* adjncy, idx_t* vwgt, idx_t* options, idx_t* sepsize,
                                 idx_t* part);

int METIS_NodeND(idx_t* nvtxs, idx_t* xadj, idx_t* adjncy, idx_t* vwgt, idx_t* options, idx_t* perm, idx_t* iperm) {
  (void)nvtxs; (void)xadj; (void)adjncy; (void)vwgt; (void)options; (void)perm; (void)iperm;
  return kMetisError;
}

int METIS_ComputeVertexSeparator(idx_t* nvtxs, idx_t* xadj, idx_t* adjncy, idx_t* vwgt, idx_t* options, idx_t* sepsize,
                                 idx_t* part) {
  (void)nvtxs; (void)xadj; (void)adjncy; (void)vwgt; (void)options; (void)sepsize; (void)part;
  return kMetisError;
}
