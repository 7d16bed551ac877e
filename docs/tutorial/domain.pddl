;; A robot that tidies up: it carries a thing from one place to another.
(define (domain tidy)
  (:requirements :strips :typing :durative-actions)
  (:types robot thing place)
  (:predicates (on ?t - thing ?p - place))

  (:durative-action carry
    :parameters (?r - robot ?t - thing ?from ?to - place)
    :duration (= ?duration 2)
    :condition (at start (on ?t ?from))
    :effect (and (at start (not (on ?t ?from)))
                 (at end (on ?t ?to)))))
