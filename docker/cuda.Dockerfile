# wmdist CUDA image: the optional GPU learner node of deploy/ray/aws.yaml
# (`worker_image: wmdist:cuda`). Build from the repository root:
#   docker build -f docker/cuda.Dockerfile -t wmdist:cuda .
# Same install as the CPU image (`make system-deps setup`); torch comes from PyPI's
# default wheel, which bundles its CUDA libraries, so the base only needs the NVIDIA
# container environment (the driver comes from the host through the NVIDIA runtime).
FROM nvidia/cuda:12.8.1-base-ubuntu22.04

LABEL ai.wmdist.image="wmdist:cuda" \
      org.opencontainers.image.title="wmdist (CUDA)" \
      org.opencontainers.image.description="Distributed world-model agents on Ray, CUDA torch"

ENV DEBIAN_FRONTEND=noninteractive \
    PIP_NO_CACHE_DIR=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1 \
    MUJOCO_GL=egl

# Ubuntu 22.04 ships python3.11 (with venv) beside its default 3.10.
RUN apt-get update -qq \
 && apt-get install -y -qq --no-install-recommends \
      python3.11 python3.11-venv make rsync openssh-client procps ca-certificates \
 && rm -rf /var/lib/apt/lists/*

WORKDIR /opt/wmdist
COPY . /opt/wmdist
RUN make system-deps setup PYTHON=python3.11 \
 && rm -rf /var/lib/apt/lists/*

ENV PATH=/opt/wmdist/.venv/bin:$PATH
CMD ["bash"]
