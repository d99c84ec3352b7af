# wmdist CPU image: the head and CPU workers of deploy/ray/aws.yaml (`image: wmdist:cpu`).
# Build from the repository root:
#   docker build -f docker/cpu.Dockerfile -t wmdist:cpu .
# wmdist is installed by the README's own make targets (`make system-deps setup`), so the
# image holds exactly what `make test` / `make run` set up: the venv, redis-server,
# prometheus and the EGL libraries for dm_control pixels.
FROM python:3.11-slim-bookworm

LABEL ai.wmdist.image="wmdist:cpu" \
      org.opencontainers.image.title="wmdist (CPU)" \
      org.opencontainers.image.description="Distributed world-model agents on Ray, CPU torch"

# PIP_EXTRA_INDEX_URL: the CPU build of torch (a fraction of the default CUDA wheel's size).
ENV DEBIAN_FRONTEND=noninteractive \
    PIP_NO_CACHE_DIR=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1 \
    PIP_EXTRA_INDEX_URL=https://download.pytorch.org/whl/cpu \
    MUJOCO_GL=egl

# make runs the install; rsync and ssh are what `ray up` uses to reach a container.
RUN apt-get update -qq \
 && apt-get install -y -qq --no-install-recommends make rsync openssh-client procps \
 && rm -rf /var/lib/apt/lists/*

WORKDIR /opt/wmdist
COPY . /opt/wmdist
RUN make system-deps setup PYTHON=python3.11 \
 && rm -rf /var/lib/apt/lists/*

# `ray`, `wmdist` and the venv's python first on PATH for `ray up` commands and jobs.
ENV PATH=/opt/wmdist/.venv/bin:$PATH
CMD ["bash"]
