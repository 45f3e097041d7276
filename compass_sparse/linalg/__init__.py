"""Sparse and dense linear algebra shared by the passes.

``blas``      one BLAS thread for small dense kernels (threadpoolctl, one controller);
``csc``       CSC matrices built from trusted arrays, canonical patterns, M x;
``direct``    the sparse direct solvers of the direct Newton step and the crash (KLU with
              its symbolic analyses kept per pattern, SuperLU with COLAMD);
``matching``  maximum bipartite matching (structural rank, zero-free diagonals);
``coloring``  column colouring for sparse finite differences;
``_csc_kernels`` the compiled loops over CSC arrays that the modules above and the passes
              call.

The basis manager's own LU backends (SuperLU, UMFPACK, the factorization budget) are
:mod:`compass_sparse.basis.backends`: they serve the factors the manager updates.
"""
