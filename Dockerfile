# dolfinx_mortar on Debian stable's dolfinx (0.9), the same packages as tools/run uses.
#   docker build -t dolfinx_mortar .
#   docker run --rm -v "$PWD/results:/opt/dolfinx_mortar/results" dolfinx_mortar          # make demo
#   docker run --rm dolfinx_mortar make test
FROM debian:trixie

ENV DEBIAN_FRONTEND=noninteractive \
    OMPI_ALLOW_RUN_AS_ROOT=1 \
    OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 \
    OMPI_MCA_btl=self,vader \
    OMPI_MCA_btl_vader_single_copy_mechanism=none \
    PRTE_MCA_rmaps_default_mapping_policy=:oversubscribe \
    OMP_NUM_THREADS=1 \
    SCOTCH_PTHREAD_NUMBER=1

COPY tools/debian-packages.txt tools/pip-packages.txt /tmp/dolfinx_mortar/
RUN apt-get update \
    && sed -e 's/#.*//' /tmp/dolfinx_mortar/debian-packages.txt | xargs apt-get install -y --no-install-recommends \
    && rm -rf /var/lib/apt/lists/*
# behind a TLS-intercepting proxy: --build-arg PIP_CERT=/path/to/its/ca-bundle (mounted into the build)
ARG PIP_CERT=
RUN if [ -z "$PIP_CERT" ]; then unset PIP_CERT; fi; \
    sed -e 's/#.*//' /tmp/dolfinx_mortar/pip-packages.txt | xargs -r python3 -m pip install --no-cache-dir --break-system-packages

WORKDIR /opt/dolfinx_mortar
COPY . .
RUN python3 -m pip install --no-cache-dir --break-system-packages --no-deps --no-build-isolation . \
    && python3 -c "import dolfinx_mortar, dolfinx; print('dolfinx', dolfinx.__version__)"

CMD ["make", "demo"]
